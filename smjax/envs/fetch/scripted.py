"""The fully scripted stacking hierarchy: every level played by hand-written rules.

Level 1 picks ``place_i`` for the lowest block not in place (a tower is built bottom
up) and runs it until it is satisfied or times out (80 ticks). With ``levels=2`` the
``place_i`` option itself chooses among ``reach_i`` / ``pick_i`` / ``release_i`` (release
once the block is on its goal, pick once it is reached or held, else reach), each run
until its own termination test or timeout; with ``levels=1`` the ``place_i`` controller
acts directly. This measures how reliable the templates are when composed exactly as
the paper's hierarchy composes them, and produces demonstrations.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from smjax.envs.fetch import controllers as ctl
from smjax.envs.fetch import templates as tp
from smjax.envs.fetch.dynamics import blocks_placed

SUB_REACH, SUB_PICK, SUB_RELEASE = 0, 1, 2
_SUB_K_MAX = jnp.asarray([tp.K_MAX["reach"], tp.K_MAX["pick"], tp.K_MAX["release"]])


@struct.dataclass
class ScriptState:
    block: jax.Array  # int32: block whose place_i runs, -1 for noop
    place_steps: jax.Array
    sub: jax.Array  # int32: SUB_* running inside place_i, -1 for none chosen yet
    sub_steps: jax.Array


def init_script_state() -> ScriptState:
    minus_one, zero = jnp.asarray(-1, jnp.int32), jnp.asarray(0, jnp.int32)
    return ScriptState(minus_one, zero, minus_one, zero)


def _per_block(fn, state, params, n: int) -> jax.Array:
    return jnp.stack([fn(state, params, i) for i in range(n)])


def scripted_action(state, params, script: ScriptState, levels: int = 2,
                    key: jax.Array | None = None, epsilon: float = 0.0):
    """One tick of the scripted hierarchy: (action float32[4], next ScriptState).

    With ``key`` and ``epsilon`` > 0 the level-1 choice explores like a DQN root: with
    probability ``epsilon`` it calls ``place_i`` for a uniformly drawn block not in place
    (the initiable ones) instead of the lowest one. This measures the score an optimal but
    exploring root can reach (the ceiling of a learner's running score).
    """
    if levels not in (1, 2):
        raise ValueError(f"levels must be 1 or 2, got {levels!r}")
    fixed = isinstance(epsilon, (int, float))  # else traced
    if fixed and not 0.0 <= epsilon <= 1.0:
        raise ValueError(f"epsilon must be in [0, 1], got {epsilon!r}")
    # a fixed 0 draws nothing: the plain scripted hierarchy (also the throughput benchmark's
    # policy) keeps its workload
    explores = key is not None and not (fixed and epsilon == 0.0)
    n = state.goals.shape[-2]
    placed = blocks_placed(state, params)
    place_done = _per_block(tp.place_satisfied, state, params, n)
    block = script.block
    safe_block = jnp.maximum(block, 0)
    top_done = (block < 0) | place_done[safe_block] | (script.place_steps >= tp.K_MAX["place"])
    first_unplaced = jnp.argmax(~placed)
    if explores:
        key_explore, key_block = jax.random.split(key)
        random_unplaced = jax.random.categorical(key_block, jnp.where(placed, -jnp.inf, 0.0))
        explore = jax.random.uniform(key_explore) < epsilon
        first_unplaced = jnp.where(explore, random_unplaced, first_unplaced)
    new_block = jnp.where(jnp.any(~placed), first_unplaced, -1).astype(jnp.int32)
    block = jnp.where(top_done, new_block, block)
    place_steps = jnp.where(top_done, 0, script.place_steps)
    sub = jnp.where(top_done, -1, script.sub)
    sub_steps = jnp.where(top_done, 0, script.sub_steps)
    safe_block = jnp.maximum(block, 0)

    # Level 2: re-choose the sub-template when it terminated (or none runs yet).
    reach_done = _per_block(tp.reach_satisfied, state, params, n)[safe_block]
    pick_done = _per_block(tp.pick_satisfied, state, params, n)[safe_block]
    release_done = _per_block(tp.release_satisfied, state, params, n)[safe_block]
    sub_done_now = jnp.stack([reach_done, pick_done, release_done])[jnp.maximum(sub, 0)]
    sub_timeout = sub_steps >= _SUB_K_MAX[jnp.maximum(sub, 0)]
    choose = (sub < 0) | sub_done_now | sub_timeout
    on_goal = _per_block(tp.release_initiation, state, params, n)[safe_block]
    near = _per_block(tp.pick_initiation, state, params, n)[safe_block]
    chosen = jnp.where(on_goal, SUB_RELEASE, jnp.where(near, SUB_PICK, SUB_REACH))
    sub = jnp.where(choose, chosen, sub).astype(jnp.int32)
    sub_steps = jnp.where(choose, 0, sub_steps)

    if levels == 2:
        table = jnp.stack([
            _per_block(ctl.reach, state, params, n),
            _per_block(ctl.pick, state, params, n),
            _per_block(ctl.release, state, params, n),
        ])  # [3, N, 4]
        action = table[sub, safe_block]
    else:
        action = _per_block(ctl.place, state, params, n)[safe_block]
    action = jnp.where(block < 0, ctl.noop(state, params), action)
    next_script = ScriptState(block.astype(jnp.int32), place_steps + 1, sub, sub_steps + 1)
    return action, next_script


def rollout(env, key: jax.Array, params, num_steps: int, levels: int = 2, epsilon: float = 0.0):
    """Reset, then play the scripted hierarchy for ``num_steps`` (no auto-reset).

    Returns (final env state, per-step rewards float32[T], per-step info dict of [T] arrays).
    Jit and vmap it (``num_steps`` and ``levels`` static; ``epsilon``: the level-1
    exploration of ``scripted_action``, 0 for none).
    """
    _, state = env.reset_env(key, params)

    def tick(carry, step_key):
        env_state, script = carry
        action, script = scripted_action(env_state, params, script, levels,
                                         jax.random.fold_in(step_key, 1), epsilon)
        _, env_state, reward, _, _, info = env.step_env(step_key, env_state, action, params)
        return (env_state, script), (reward, info["is_success"], info["score"])

    keys = jax.random.split(key, num_steps)
    (state, _), (rewards, success, score) = jax.lax.scan(
        tick, (state, init_script_state()), keys)
    return state, rewards, {"is_success": success, "score": score}
