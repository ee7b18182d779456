"""The data the hierarchical tick carries and reports: per-environment rollout state
(``EnvCarry``, ``ResetPool``), per-tick episode bookkeeping (``EpisodeEnds``, summed to
``TickStats``) and every setting of a tick (``Controls``).

They live apart from the runner so that the tick's phases (``smjax.options.phases``) and
the runner that strings them together both import them one way.
"""
from __future__ import annotations

from dataclasses import KW_ONLY, dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from smjax.core.transition import Transition
from smjax.options.stack import ExecutionStack

NO_OPTION = -1


@struct.dataclass
class EnvCarry:
    """Per-environment rollout state (leading axis B)."""

    env_state: Any
    obs: jax.Array
    stack: ExecutionStack
    learner_started: jax.Array  # bool: the learner has acted in this episode
    learner_return: jax.Array   # float: learner reward collected in this episode
    task_return: jax.Array      # float: environment reward collected in this episode
    pending: Transition         # the learner's decision still running at the last rollout end
    pool: "ResetPool | None" = None  # pre-generated episode starts (None: reset in every tick)
    # a recurrent policy's memory per option [B, O, H] (None: memoryless policies): zero
    # while the option is off the stack, advanced on its own decisions
    hidden: jax.Array | None = None


@struct.dataclass
class ResetPool:
    """Episode starts generated ahead of time (leading axis P), handed out in order.

    Generating a fresh episode start for every environment in every tick (and throwing
    it away wherever the episode goes on) costs as much as the step itself in worlds
    with procedural generation; instead ``refill`` generates P starts once (the engine
    does it before every rollout) and each reset takes the next unused one, so within
    a rollout every episode gets its own fresh start unless more than P episodes end
    (then starts are reused, oldest first).
    """

    obs: jax.Array
    state: Any
    next: jax.Array  # int32: index of the next start to hand out (mod P)


@struct.dataclass
class EpisodeEnds:
    """Per-environment episode bookkeeping of one tick (leading axis B)."""

    reset: jax.Array     # bool: the environment was reset after this tick (every reset counts)
    finished: jax.Array  # bool: an episode in which the learner acted ended
    ret: jax.Array       # float: that episode's learner return (0 where not finished)
    success: jax.Array   # float: that episode's success (0 where not finished)
    decided: jax.Array   # bool: the learner decided in this tick
    task_end: jax.Array  # bool: a whole-task episode (root at the bottom) ended naturally
    task_success: jax.Array  # float: that episode's task success (0 where not ended)


@struct.dataclass
class TickStats:
    """Sums over the batch (and over ticks once reduced)."""

    env_episodes: jax.Array
    learner_episodes: jax.Array
    learner_return: jax.Array
    learner_success: jax.Array
    learner_decisions: jax.Array
    task_episodes: jax.Array
    task_success: jax.Array

    @staticmethod
    def of(ends: EpisodeEnds) -> "TickStats":
        return TickStats(
            env_episodes=ends.reset.sum(-1).astype(jnp.int32),
            learner_episodes=ends.finished.sum(-1).astype(jnp.int32),
            learner_return=ends.ret.sum(-1),
            learner_success=ends.success.sum(-1),
            learner_decisions=ends.decided.sum(-1).astype(jnp.int32),
            task_episodes=ends.task_end.sum(-1).astype(jnp.int32),
            task_success=ends.task_success.sum(-1),
        )


@dataclass(frozen=True)
class Controls:
    """Every setting of a tick: the one source of its mode (the runner fixes only the
    program's structure). Arrays are traced, so one compile serves every level and seed;
    the fields documented as Python values are static: a program is traced per value.

    learner: option id being trained (NO_OPTION: evaluation, nobody learns).
    start: option placed at the bottom of the stack at each reset (0 = root; a template
      id starts that template directly from reset states, as bottom-up training does).
    learned: bool [num_options], options whose frozen policy is in the bank.
    gamma: float, the discount per tick (gamma**d for a teleported call of duration d); no
      default: the trainer's config is its one source. Traced where an array, so runs with
      different discounts share one compile (a sweep). Joint fine-tuning gives one per
      option (float [O]), and its record's discount is per option too.
    teleport: bool, unlearned templates with a teleport may be called (their call jumps the
      state); a traced False turns training into evaluation without another compile, a
      Python False leaves the teleports out of the program.
    continue_episodes: bool, the environment goes on when the learner's option ends; its
      next episode starts where the levels above call it again (False: it is reset).
    temperature: how frozen policies (and a learner acting frozen) pick: 0 greedy (argmax),
      else a sample at this temperature; a float, or float [O], one per option (e.g. the
      root sampling at 1 while the templates below it pick at 0.5). A Python float
      compiles only its own pick (0.0: the argmax alone).
    side_cost: float weight (or bool), a template learner is also rewarded by this times the
      decrease of its template's ``side_cost`` (None or 0: never; fine-tuning turns it on).
    acts_frozen: a Python bool, not traced: the learner picks as the bank will run it once
      frozen (at ``temperature``, no exploration; only its params are read) instead of
      exploring through the agent's ``act``: the gate's and evaluation's mode. Static
      because the two modes read different learner state (evaluation has none), so they
      cannot share one traced program.
    joint: a Python bool, not traced: every learned option learns at once (joint
      fine-tuning, ``smjax.options.joint``): the tick takes a learner state per option
      (leading axis O) instead of one learner and a bank, each learned option explores
      through its own ``act``, and the tick's record has one row per option ([B, O]).
      ``learner`` is NO_OPTION then.
    """

    learner: jax.Array
    start: jax.Array
    learned: jax.Array
    gamma: jax.Array | float
    _: KW_ONLY
    teleport: jax.Array | bool = True
    continue_episodes: jax.Array | bool = False
    temperature: jax.Array | np.ndarray | float = 0.0
    side_cost: jax.Array | float | None = None
    acts_frozen: bool = False
    joint: bool = False

    def resets_on_learner_end(self) -> jax.Array | bool:
        """Whether an environment is reset when the learner's option ends (a Python bool
        stays one)."""
        keep = self.continue_episodes
        return (not keep) if isinstance(keep, bool) else ~keep

    def teleports(self) -> bool:
        """Whether the program holds the teleports at all (a Python False leaves them out)."""
        return not (isinstance(self.teleport, bool) and not self.teleport)
