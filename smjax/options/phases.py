"""The phases of one hierarchical tick, as pure functions of arrays.

``HierarchyRunner.tick`` strings them together; each is small enough to test on a
hand-built situation (tests/test_runner_phases.py):

  decide   walk the execution stack from the top until a primitive step is fixed: which
           option is pushed, which primitive is taken, which template is teleported or
           plays its scripted controller, and whether the learner chose (unbatched).
  realise  turn that into the environment's action (smjax.options.realise).
  step     one environment step for every environment.
  pop      count the tick on every stack entry; the lowest entry that is satisfied,
           failed or out of ticks ends, with everything above it.
  account  rewards, discounts, returns, episode ends: the learner's training record
           and the episode bookkeeping.

They take what they need as arguments (no runner, no templates, no learner), so the
same numbers come out whoever calls them.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from smjax.options.carry import NO_OPTION, EpisodeEnds
from smjax.options.stack import (
    ExecutionStack, stack_contains, stack_push, stack_tick, stack_top, stack_truncate,
)


# ---- decide -------------------------------------------------------------------------
class Decision(NamedTuple):
    """One environment's outcome of the decision cascade."""

    stack: ExecutionStack       # with this tick's calls pushed
    primitive: jax.Array        # int32: the primitive taken (0 where none was)
    teleported: jax.Array       # int32: the template teleported (NO_OPTION: none)
    scripted: jax.Array         # int32: the template whose controller acts (NO_OPTION: none)
    learner_decided: jax.Array  # bool: the learner chose in this tick
    chose: jax.Array | None = None  # bool [O]: the options that chose in this tick


def deciding_options(learned: jax.Array, has_policy: jax.Array, has_teleport: jax.Array,
                     teleport_on: jax.Array | bool) -> jax.Array:
    """bool [O]: options that choose among their children when on the stack (besides the
    learner): the learned ones, and those with a scripted policy unless teleported instead
    (a scripted policy, like a controller, gives way to a teleport where teleports are on)."""
    return learned | (has_policy & ~(has_teleport & teleport_on))


def pushable_options(learned: jax.Array, learner: jax.Array, has_controller: jax.Array,
                     has_teleport: jax.Array, teleport_on: jax.Array | bool) -> jax.Array:
    """bool [O]: options that go on the stack when called: learned ones, the learner, and
    scripted ones that are not teleported instead (the rest are teleported)."""
    scripted_ok = has_controller & ~(has_teleport & teleport_on)
    return learned | (jnp.arange(learned.shape[0]) == learner) | scripted_ok


def decide(stack: ExecutionStack, frozen_choice: jax.Array, learner_choice: jax.Array, *,
           learner: jax.Array, learned: jax.Array, pushable: jax.Array, callable_: jax.Array,
           num_primitives: int) -> Decision:
    """Walk down from the stack top until a primitive step is fixed (one environment).

    ``frozen_choice [O]``: what each frozen (or scripted) policy picks now (action ids:
    primitives first, then templates); ``learner_choice``: the learner's pick.
    ``learned``: the options that choose (``deciding_options``: learned, or with a
    scripted policy). A learned option or the learner chooses; an unlearned option on the
    stack plays its script (the walk stops there). A chosen template is pushed
    (``pushable & callable_``; the walk goes on one level deeper) or else teleported (the
    walk stops). The stack is at most its
    capacity deep, so that many steps always reach a decision.

    Writes go through masks, not indexed writes (a scatter is a kernel of its own on a
    GPU); reads stay indexed: read through masks or chains of selects, the walk made a CPU
    rollout 2.5-17x slower (benchmarks/RESULTS.md, "Fewer kernels in a tick").
    """
    num_options = learned.shape[0]
    decided = jnp.asarray(False)
    learner_decided = jnp.asarray(False)
    primitive = jnp.asarray(0, jnp.int32)
    teleported = jnp.asarray(NO_OPTION, jnp.int32)
    scripted = jnp.asarray(NO_OPTION, jnp.int32)
    chose = jnp.zeros((num_options,), bool)
    for _ in range(stack.capacity):
        top = jnp.maximum(stack_top(stack), 0)
        is_learner = top == learner
        is_scripted = ~is_learner & ~learned[top]
        choice = jnp.where(is_learner, learner_choice, frozen_choice[top])
        open_ = ~decided
        run_script = open_ & is_scripted
        chooses = open_ & ~is_scripted
        learner_decided = learner_decided | (chooses & is_learner)
        chose = chose | ((jnp.arange(num_options) == top) & chooses)  # a mask: no scatter
        is_prim = choice < num_primitives
        tpl = jnp.clip(choice - num_primitives + 1, 0, num_options - 1)
        push = chooses & ~is_prim & pushable[tpl] & callable_[tpl]
        teleport = chooses & ~is_prim & ~push
        take_prim = chooses & is_prim
        scripted = jnp.where(run_script, top, scripted)
        primitive = jnp.where(take_prim, choice, primitive)
        teleported = jnp.where(teleport, tpl, teleported)
        decided = decided | run_script | take_prim | teleport
        stack = stack_push(stack, tpl, push)
    return Decision(stack, primitive, teleported, scripted, learner_decided, chose)


# ---- step ---------------------------------------------------------------------------
def step(env, env_params, key: jax.Array, state: Any, action: jax.Array):
    """One environment step for each of the B environments (a key each):
    ``(obs, state, reward, terminated, truncated, info)``."""
    B = action.shape[0]
    return jax.vmap(env.step_env, (0, 0, 0, None))(jax.random.split(key, B), state, action,
                                                  env_params)


# ---- pop ----------------------------------------------------------------------------
class Popped(NamedTuple):
    """The stacks after this tick's ends (leading axis B)."""

    stack: ExecutionStack
    first_end: jax.Array      # int32: lowest ended position (capacity where none ended)
    learner_on: jax.Array     # bool: the learner was on the stack (before the pops)
    learner_ended: jax.Array  # bool: the learner's entry, or one below it, ended


def pop(stack: ExecutionStack, stop: jax.Array, k_max: jax.Array, learner: jax.Array) -> Popped:
    """Count the tick on every live entry, then end the lowest entry whose option is
    ``stop`` [B, O] (satisfied or failed in the new state) or has run ``k_max[option]``
    ticks, and everything above it: a caller that ends takes its callees with it."""
    stack = jax.vmap(stack_tick)(stack)
    depth_cap = stack.option.shape[-1]
    opt = jnp.maximum(stack.option, 0)
    live = jnp.arange(depth_cap)[None, :] < stack.depth[:, None]
    ended = live & (jnp.take_along_axis(stop, opt, 1) | (stack.steps >= k_max[opt]))
    first_end = jnp.where(ended.any(1), jnp.argmax(ended, 1), depth_cap)
    learner_on = jax.vmap(stack_contains, (0, None))(stack, learner)
    learner_pos = jnp.argmax(stack.option == learner, 1)
    learner_ended = learner_on & (first_end <= learner_pos)
    return Popped(jax.vmap(stack_truncate)(stack, first_end), first_end, learner_on,
                  learner_ended)


# ---- account ------------------------------------------------------------------------
def tick_discount(teleported: jax.Array, nominal: jax.Array, gamma) -> jax.Array:
    """Per-tick discount [B]: gamma, or gamma**d where a template was teleported (d = its
    nominal duration), so a jump weighs as the steps it stands for (SMDP). With one
    gamma per option ([O]: joint fine-tuning, each option at its own level's), [B, O]."""
    tp_steps = jnp.where(teleported >= 0, nominal[jnp.maximum(teleported, 0)], 1.0)
    if jnp.ndim(gamma):
        return jnp.asarray(gamma)[None, :] ** tp_steps[:, None]
    return gamma ** tp_steps


class Accounts(NamedTuple):
    """One tick's bookkeeping (leading axis B)."""

    reset: jax.Array           # bool: the environment starts a new episode
    learner_done: jax.Array    # bool: the learner's episode ended (Transition.done)
    reward: jax.Array          # float: the learner's reward (Transition.reward)
    started: jax.Array         # bool: the learner has acted in the episode that goes on
    learner_return: jax.Array  # float: its return so far (0 after an end)
    task_return: jax.Array     # float: the environment's return so far (0 after a reset)
    ends: EpisodeEnds


def account(*, started: jax.Array, learner_return: jax.Array, task_return: jax.Array,
            decided: jax.Array, reward: jax.Array, env_done: jax.Array, popped: Popped,
            learner_satisfied: jax.Array, shaping: jax.Array | float,
            info_success: jax.Array | None, learner: jax.Array, start: jax.Array,
            reset_on_learner_end: jax.Array | bool) -> Accounts:
    """Rewards, returns and episode ends of one tick, from what the other phases found.

    The learner's reward is the environment's when it is the root option, else its
    template's F_o (``learner_satisfied`` while it is on the stack), plus ``shaping``.
    Its episode is one run of its option: it ends with the environment's episode or when
    the option ends; it only counts once the learner has acted in it (evaluation, with
    no learner, counts every episode). ``started``, ``learner_return`` and
    ``task_return`` are the carried values before this tick.
    """
    task_end = env_done | (popped.first_end == 0)  # the root (or start option) ended
    reset = task_end | (popped.learner_ended & reset_on_learner_end)
    is_root = learner <= 0
    learner_reward = jnp.where(
        is_root, reward.astype(jnp.float32),
        (popped.learner_on & learner_satisfied).astype(jnp.float32),
    )
    started = started | decided | (learner < 0)
    ep_return = learner_return + jnp.where(started, learner_reward, 0.0)
    task_return = task_return + reward.astype(jnp.float32)
    learner_done = reset | popped.learner_ended
    finished = learner_done & started
    # Success of a finished episode: the template's F_o (its return) for a template
    # learner; for the root, the task's success where there is one (the hierarchy's
    # declared success, else the environment's info["success"], e.g. Fetch's fraction of
    # blocks placed: template_fields.task_success), else the episode return.
    if info_success is not None:
        task_success = jnp.asarray(info_success, jnp.float32)
        success = jnp.where(is_root, task_success, ep_return)
    else:
        task_success, success = task_return, ep_return
    # A whole-task episode counts where the root is at the bottom of the stack and the
    # episode ended by itself (not cut because a learner's option ended).
    task_end = task_end & (start == 0)
    ends = EpisodeEnds(
        reset=reset, finished=finished, ret=jnp.where(finished, ep_return, 0.0),
        success=jnp.where(finished, success, 0.0), decided=decided,
        task_end=task_end, task_success=jnp.where(task_end, task_success, 0.0),
    )
    return Accounts(
        reset=reset, learner_done=learner_done,
        reward=jnp.where(started, learner_reward + shaping, 0.0),
        started=started & ~learner_done,
        learner_return=jnp.where(learner_done, 0.0, ep_return),
        task_return=jnp.where(reset, 0.0, task_return),
        ends=ends,
    )
