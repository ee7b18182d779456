"""A trained hierarchy loaded from its saved policy, without a trainer: it acts (pure
functions, usable under ``jit`` and ``vmap``), evaluates its teleport-free task success
and renders episodes.

    policy = smjax.load_policy("runs/wood")
    params = policy.params(0)                    # the hierarchy training seed 0 learned
    carry = policy.reset(key, num_envs=16)       # fresh episodes
    action = policy.act(params, carry, key)      # the primitive actions it takes now
    carry, ends = policy.step(params, carry, key)  # one environment step, stack and all
    policy.evaluate(episodes=256, seed=1)        # {"success": [per seed], "return": ...}
    frames, total = policy.render(seed_index=0)

The policy acts as the run's final evaluation did (the run's frozen-policy mode, no
teleports, scripted leaf controllers where the hierarchy has them), with the same
compiled episodes program, so ``evaluate()`` with its defaults reproduces results.json's
``final_success``.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from smjax.options.carry import NO_OPTION, Controls, EnvCarry, EpisodeEnds
from smjax.options.episodes import early_stop_bounds, eval_temperatures, seed_batched_episodes


class PolicyParams(NamedTuple):
    """What a saved hierarchy acts with: every option's parameters (``bank``, leaves
    [O, ...]) and which options act by their own policy (``learned``, bool [O]); with a
    leading seed axis where they hold every seed's."""

    bank: Any
    learned: jax.Array


class SavedPolicy:
    """A saved hierarchy per training seed; made by :func:`smjax.load_policy`."""

    def __init__(self, meta: dict, runner, params: PolicyParams, eval_keys: jax.Array):
        self.meta = meta
        self.runner = runner
        self.env, self.env_params, self.hierarchy = runner.env, runner.env_params, runner.h
        self.task: str = meta["task"]
        self.seeds: list[int] = list(meta["seeds"])
        evaluation = meta["evaluation"]
        # how the frozen policies pick: as in the run's final evaluation
        self.temperature = eval_temperatures(evaluation["policy"], self.hierarchy.num_options,
                                             evaluation["option_temperature"])
        # the run's discount (policies saved before it was part of the evaluation's
        # description kept it with the runner's settings)
        self.gamma = float(evaluation["gamma"] if "gamma" in evaluation
                           else meta["runner"]["gamma"])
        self._all = params
        self._eval_keys = eval_keys
        self._episodes = seed_batched_episodes(runner, self.gamma)
        self._step = jax.jit(self.step)

    def __repr__(self) -> str:
        return (f"SavedPolicy({self.task!r}, hierarchy {self.meta['hierarchy']!r}, "
                f"seeds {self.seeds})")

    # ---- acting: pure functions of their arguments -------------------------------------
    def params(self, seed_index: int | None = None) -> PolicyParams:
        """The hierarchy of training seed ``seeds[seed_index]``; None: every seed's
        (leading axis S, for ``jax.vmap`` over seeds)."""
        if seed_index is None:
            return self._all
        if not 0 <= seed_index < len(self.seeds):
            raise ValueError(f"seed_index must be in [0, {len(self.seeds)}), got {seed_index}")
        return jax.tree.map(lambda x: x[seed_index], self._all)

    def controls(self, learned: jax.Array) -> Controls:
        """The tick's switches for acting: nobody learns, no teleports, the frozen
        policies at the evaluation's temperatures, episodes that run to the task's end."""
        return Controls(jnp.asarray(NO_OPTION), jnp.asarray(0, jnp.int32), learned,
                        gamma=self.gamma, teleport=jnp.asarray(False),
                        continue_episodes=jnp.asarray(False), temperature=self.temperature,
                        acts_frozen=True)

    def reset(self, key: jax.Array, num_envs: int = 1) -> EnvCarry:
        """Fresh episodes of ``num_envs`` environments, the root on every stack."""
        no_options = jnp.zeros((self.hierarchy.num_options,), bool)
        return self.runner.reset(key, self.controls(no_options), num_envs)

    def act(self, params: PolicyParams, carry: EnvCarry, key: jax.Array) -> jax.Array:
        """The primitive action [B, ...] the hierarchy takes in ``carry``'s states: the
        one ``step`` with the same key steps with."""
        return self.runner.primitive_actions(carry, key, None, params.bank,
                                             self.controls(params.learned))

    def step(self, params: PolicyParams, carry: EnvCarry,
             key: jax.Array) -> tuple[EnvCarry, EpisodeEnds]:
        """One primitive step of every environment: the options on each stack decide, the
        environment steps, finished options pop and ended episodes restart."""
        carry, _, ends = self.runner.tick(carry, key, None, params.bank,
                                          self.controls(params.learned))
        return carry, ends

    # ---- evaluation and rendering ------------------------------------------------------
    def evaluate(self, episodes: int | None = None, seed: int | None = None,
                 max_ticks: int | None = None) -> dict:
        """Every seed's hierarchy alone (no teleports, nobody learning) on ``episodes``
        fresh episodes each (default: the run's ``eval_envs``), each cut at ``max_ticks``
        (default: the run's ``eval_max_ticks``; an unfinished episode is a failure).
        ``seed``: the key of the episodes (default: the run's final evaluation's, which
        reproduces results.json's ``final_success``). Returns per seed ``success``,
        ``return`` and ``completed`` (the share of episodes that ended)."""
        evaluation = self.meta["evaluation"]
        episodes = evaluation["episodes"] if episodes is None else episodes
        max_ticks = evaluation["max_ticks"] if max_ticks is None else max_ticks
        for name, value in (("episodes", episodes), ("max_ticks", max_ticks)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        S = len(self.seeds)
        if seed is None:
            keys = self._eval_keys
        elif isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
            raise ValueError(f"seed must be an integer in [0, 2**32), got {seed!r}")
        else:
            keys = jax.random.split(jax.random.PRNGKey(seed), S)
        bank, learned = self._all
        temperatures = jnp.broadcast_to(self.temperature, (S,) + self.temperature.shape)
        # the arguments of the run's own evaluation (``Engine.evaluate``), in its types
        args = (keys, jax.tree.map(lambda p: p[:, 0], bank), bank, learned,
                jnp.full((S,), NO_OPTION, jnp.int32), jnp.zeros((S,), jnp.int32),
                jnp.asarray(False), temperatures, jnp.asarray(max_ticks),
                jnp.zeros((S,), bool), early_stop_bounds([None] * S))
        result = jax.device_get(self._episodes(*args, episodes))
        return {"task": self.task, "seeds": self.seeds, "episodes": episodes,
                "success": [float(x) for x in result["success"]],
                "return": [float(x) for x in result["return"]],
                "completed": [float(x) for x in result["completed"]]}

    def render(self, seed_index: int = 0, max_steps: int = 200,
               seed: int = 0) -> tuple[list[np.ndarray], float]:
        """RGB frames (uint8 [H, W, 3]) of one episode of seed ``seeds[seed_index]``'s
        hierarchy, at most ``max_steps`` steps, and the episode's return."""
        params = self.params(seed_index)
        key, k_reset = jax.random.split(jax.random.PRNGKey(seed))
        carry = self.reset(k_reset, 1)
        states = [jax.tree.map(lambda x: x[0], carry.env_state)]
        ret = 0.0
        for _ in range(max_steps):
            key, k = jax.random.split(key)
            new, ends = self._step(params, carry, k)
            if bool(ends.reset[0]):  # the next state already belongs to a new episode
                ret = float(ends.ret[0])
                break
            carry = new
            ret = float(carry.learner_return[0])  # (nobody learns: the episode's return)
            states.append(jax.tree.map(lambda x: x[0], carry.env_state))
        return [np.asarray(self.env.render(s, self.env_params), np.uint8) for s in states], ret
