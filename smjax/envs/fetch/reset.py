"""Episode starts: a tower of goals, blocks scattered on the table, the gripper at its
start with open fingers (``initial_state``), and the distributions they are drawn from.

* goal_0 = gripper start xy + U(-r, r)^2 on the table (z of a block resting on it),
  goal_i = goal_0 + i * 0.05 z (a tower).
* block i at gripper start xy + U(-r, r)^2 on the table, at least
  ``min_gripper_distance`` (xy) from the gripper, and at least ``min_block_distance``
  from every earlier block and from goal_0's footprint.

Block-to-block and block-to-goal distances use the Chebyshev (max |dx|, |dy|) norm: two
axis-aligned 5 cm cubes are disjoint iff that distance exceeds 0.05, while a Euclidean
0.05 would allow overlapping cubes (dx = dy = 0.036). The default 0.055 therefore
implies the reference's Euclidean >= 0.05 and leaves a 5 mm gap.

Rejection sampling is vectorised: ``spawn_candidates`` candidates per block are drawn at
once and the first valid one is taken (a Python loop over the static block count only).
If no candidate is valid the last candidate is used (the spacing rule is then broken);
measured: 0 violations in 20,000 resets for each of N = 3, 4, 5 and 6.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from mujoco import mjx

from smjax.envs.fetch import model as fm
from smjax.envs.fetch.dynamics import blocks_placed
from smjax.envs.fetch.model import BLOCK_HALF, BLOCK_REST_Z, GRIPPER_START
from smjax.envs.fetch.types import FetchConfig, FetchParams, FetchState


def sample_goals(key: jax.Array, params: FetchParams, num_blocks: int) -> jax.Array:
    """float32[N, 3]: the goal tower."""
    start_xy = jnp.asarray(GRIPPER_START[:2], jnp.float32)
    xy = start_xy + jax.random.uniform(
        key, (2,), minval=-params.spawn_range, maxval=params.spawn_range
    )
    base = jnp.concatenate([xy, jnp.asarray([BLOCK_REST_Z], jnp.float32)])
    levels = jnp.arange(num_blocks, dtype=jnp.float32) * (2 * BLOCK_HALF)
    return base[None, :] + jnp.stack(
        [jnp.zeros(num_blocks), jnp.zeros(num_blocks), levels], axis=-1
    )


def sample_blocks(
    key: jax.Array, goal0_xy: jax.Array, params: FetchParams, config: FetchConfig
) -> jax.Array:
    """float32[N, 2]: block xy positions on the table satisfying the spacing rules."""
    start_xy = jnp.asarray(GRIPPER_START[:2], jnp.float32)
    n, c = config.num_blocks, config.spawn_candidates
    keys = jax.random.split(key, n)
    chosen: list[jax.Array] = []
    for i in range(n):  # static loop over the block count
        cand = start_xy + jax.random.uniform(
            keys[i], (c, 2), minval=-params.spawn_range, maxval=params.spawn_range
        )
        ok = jnp.linalg.norm(cand - start_xy, axis=-1) >= params.min_gripper_distance
        ok &= jnp.max(jnp.abs(cand - goal0_xy), axis=-1) >= params.min_block_distance
        for prev in chosen:
            ok &= jnp.max(jnp.abs(cand - prev), axis=-1) >= params.min_block_distance
        first_ok = jnp.argmax(ok)
        pick = jnp.where(jnp.any(ok), first_ok, c - 1)
        chosen.append(cand[pick])
    return jnp.stack(chosen)


def initial_state(key: jax.Array, params: FetchParams, config: FetchConfig,
                  mjx_model: mjx.Model, data0: mjx.Data) -> FetchState:
    """A fresh episode: goals and blocks drawn, gripper at its start, fingers open, at rest.

    ``data0`` is ``mjx.make_data(mjx_model)``; the kinematics are computed
    (``mjx.forward``) so the state can be observed before the first step.
    """
    key_goal, key_blocks = jax.random.split(key)
    goals = sample_goals(key_goal, params, config.num_blocks)
    blocks_xy = sample_blocks(key_blocks, goals[0, :2], params, config)
    start = jnp.asarray(fm.GRIPPER_START, jnp.float32)
    n = config.num_blocks
    block_qpos = jnp.concatenate(
        [blocks_xy, jnp.full((n, 1), fm.BLOCK_REST_Z, jnp.float32),
         jnp.tile(jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32), (n, 1))], axis=-1)
    open_fingers = jnp.full((2,), fm.FINGER_RANGE[1], jnp.float32)
    qpos = jnp.concatenate([
        start, jnp.asarray([1.0, 0.0, 0.0, 0.0], jnp.float32), open_fingers,
        block_qpos.ravel()])
    data = data0.replace(
        qpos=qpos,
        qvel=jnp.zeros_like(data0.qvel),
        ctrl=open_fingers,
        mocap_pos=start[None, :],
        mocap_quat=jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32),
    )
    data = mjx.forward(mjx_model, data)
    state = FetchState(data=data, goals=goals, step=jnp.zeros((), jnp.int32),
                       placed=jnp.zeros((n,), bool))
    return state.replace(placed=blocks_placed(state, params))
