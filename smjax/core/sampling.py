"""Small sampling kernels that stay cheap under ``vmap`` on every backend."""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp


def choose_uniform(key: jax.Array, mask: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Index of a uniformly chosen True entry of a flat bool ``mask`` and the number of
    True entries (index 0 when there are none).

    Two-level inverse-CDF: pick a row of a ~sqrt(n) x sqrt(n) view by its count, then a
    column within it. A flat ``jnp.cumsum`` lowers to a reduce-window whose cost grows
    with n squared on XLA:CPU (4x slower than this at n = 576); random scores + argmax
    costs n random draws (10x slower).
    """
    n = mask.shape[-1]
    cols = max(1, math.isqrt(n - 1) + 1) if n > 1 else 1
    rows = -(-n // cols)
    grid = jnp.pad(mask.astype(jnp.int32), (0, rows * cols - n)).reshape(rows, cols)
    row_counts = grid.sum(1)
    running = jnp.cumsum(row_counts)
    count = running[-1]
    pick = jnp.minimum((jax.random.uniform(key) * count.astype(jnp.float32)).astype(jnp.int32),
                       jnp.maximum(count - 1, 0))
    row = jnp.argmax(running > pick)
    within = pick - (running[row] - row_counts[row])
    col = jnp.argmax(jnp.cumsum(grid[row]) > within)
    return jnp.where(count > 0, row * cols + col, 0), count


def key_words(key: jax.Array) -> jax.Array:
    """The uint32 words of a typed or raw (uint32) PRNG key, flat (for cheap hash-based
    random streams that environments derive from a step key)."""
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    return jnp.asarray(key).reshape(-1).astype(jnp.uint32)
