"""Craft's episode starts: world generation (the reference's order, at a cost that fits
inside every step) and the initial state (a fresh world, or the fixed map of the params).

Order (docs/environments.md, Craft): for island/cave tasks the treasure at (x0, 1) with x0
uniform in 1..10, every empty cell of its 3 x 3 neighbourhood becomes water (gold) or stone
(gem); then 4 each of iron, grass, wood, rock at uniform free cells, then workshops 0, 1, 2,
then the agent at a free cell facing DOWN.

Sequential uniform placement onto distinct free cells is the same distribution as the first
20 entries of a uniform random permutation of the free cells, so we take 21 draws of a
Fisher-Yates shuffle over a *virtual* list of the free cells (closed form, no 100-element
array): ``partial_shuffle``.

Why not ``jax.random``: the auto-resetting ``step`` builds a fresh world on every step (under
``vmap`` both sides of the reset select run), so generation sits on the hot path. Its 21
uniform numbers come from a counter-based integer hash (murmur3's finaliser) of the key's
bits: a few integer ops each instead of threefry's ~100. Same key, same world.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.env import select_tree
from smjax.core.sampling import key_words
from smjax.envs.craft import constants as C
from smjax.envs.craft.types import CraftParams, CraftState

N = C.GRID_SIZE
NUM_RESOURCES_EACH = 4
RESOURCE_KINDS = tuple(C.KIND_ID[k] for k in ("iron", "grass", "wood", "rock"))
# Kinds placed at free cells, in order; the agent is the 20th draw.
PLACED_KINDS = np.array(
    [k for k in RESOURCE_KINDS for _ in range(NUM_RESOURCES_EACH)] + list(C.WORKSHOPS),
    np.uint8,
)
NUM_DRAWS = len(PLACED_KINDS) + 1


def _boundary_grid() -> np.ndarray:
    grid = np.zeros((N, N), np.uint8)
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = C.BOUNDARY
    return grid


BASE_GRID = _boundary_grid()
_GOLDEN = np.uint32(0x9E3779B9)


def _fmix32(h: jax.Array) -> jax.Array:
    h = h ^ (h >> 16)
    h = h * np.uint32(0x85EBCA6B)
    h = h ^ (h >> 13)
    h = h * np.uint32(0xC2B2AE35)
    return h ^ (h >> 16)


def hash_uniforms(key: jax.Array, n: int) -> jax.Array:
    """``n`` float32 numbers in [0, 1) from a counter-based hash of the key."""
    words = key_words(key)
    seed = np.uint32(0x3C6EF372)
    for i in range(words.shape[0]):
        seed = _fmix32(seed ^ words[i]) + _GOLDEN
    counters = jnp.arange(1, n + 1, dtype=jnp.uint32) * _GOLDEN
    bits = _fmix32(_fmix32(seed + counters) ^ words[-1])
    return (bits >> 8).astype(jnp.float32) * np.float32(2.0**-24)


def _uniform_int(u: jax.Array, n: jax.Array) -> jax.Array:
    """floor(u * n) for u in [0, 1), guarded against float rounding up to n."""
    return jnp.minimum((u * n.astype(jnp.float32)).astype(jnp.int32), n - 1)


def _div_small(a: jax.Array, b: jax.Array) -> jax.Array:
    """a // b for 0 <= a < 2**20, 1 <= b: a float divide (vectorises; integer division on
    CPU does not, and would be the most expensive op of world generation)."""
    q = ((a.astype(jnp.float32) + 0.5) / b.astype(jnp.float32)).astype(jnp.int32)
    return q


def _free_cell(k: jax.Array, col_lo: jax.Array, width: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Cell (x, y) of entry k of the virtual free-cell list.

    Entries 0..79 are rows 3..10 (never touched by the treasure's 3 x 3 neighbourhood);
    the rest are rows 1..2 without the columns col_lo .. col_lo + width - 1 it covers.
    """
    upper = k < 80
    per_row = 10 - width
    k_low = jnp.maximum(k - 80, 0)
    row = _div_small(k_low, per_row)
    j = k_low - row * per_row
    x_low = jnp.where(j < col_lo - 1, j + 1, j + 1 + width)
    k_up = _div_small(k, jnp.int32(10))
    x = jnp.where(upper, 1 + k - 10 * k_up, x_low)
    y = jnp.where(upper, 3 + k_up, 1 + row)
    return x, y


def partial_shuffle(u: jax.Array, n: jax.Array) -> jax.Array:
    """The first ``T = len(u)`` entries of a Fisher-Yates shuffle of ``[0, n)``: draw ``t``
    takes position ``j_t = t + floor(u_t (n - t))`` and moves the value at ``t`` there.

    The positions are known from ``u`` alone, so the swaps are found at once rather than
    one after another (a sequence of ``T`` draws, each looking up the ``t`` swaps before
    it, is ~T^2 operations unrolled into every program that resets, and compiles slowly):
    the value at position ``p`` before draw ``t`` is the value moved by the last draw
    ``t' < t`` with ``j_t' = p`` (else ``p``), and the value draw ``t'`` moved is, by the
    same rule, the one at position ``t'`` before it: following those links back from
    ``t'`` ends at the position the value started at (pointer doubling, log2 T steps)."""
    T = u.shape[0]
    t = jnp.arange(T, dtype=jnp.int32)
    j = t + _uniform_int(u, n - t)

    def last_draw_at(p: jax.Array) -> jax.Array:
        """Per draw t: the last draw before t that took position p[t], or -1."""
        hits = (j[None, :] == p[:, None]) & (t[None, :] < t[:, None])
        return jnp.max(jnp.where(hits, t[None, :], -1), axis=1)

    # moved[t]: the value draw t moved from position t (where it started: a root)
    link = last_draw_at(t)
    moved = jnp.where(link < 0, t, link)
    for _ in range(max(T - 1, 1).bit_length()):
        moved = moved[moved]
    at = last_draw_at(j)
    return jnp.where(at < 0, j, moved[jnp.maximum(at, 0)])


def generate(key: jax.Array, world: str) -> tuple[jax.Array, jax.Array]:
    """A fresh map: (grid uint8 [12, 12], agent pos int32 [2]). ``world`` is static."""
    if world not in ("plain", "island", "cave"):
        raise ValueError(f"world must be 'plain', 'island' or 'cave', got {world!r}")
    u = hash_uniforms(key, NUM_DRAWS + 1)
    flat = jnp.asarray(BASE_GRID).reshape(-1)
    if world == "plain":
        col_lo, width = jnp.int32(1), jnp.int32(0)
    else:
        x0 = 1 + _uniform_int(u[NUM_DRAWS], jnp.int32(10))
        col_lo = jnp.maximum(x0 - 1, 1)
        width = jnp.minimum(x0 + 1, N - 2) - col_lo + 1
        treasure = C.GOLD if world == "island" else C.GEM
        border = C.WATER if world == "island" else C.STONE
        # The 3 x 3 neighbourhood: row 0 and columns 0/11 are boundary and stay so.
        dx = jnp.array([-1, 0, 1, -1, 0, 1], jnp.int32)
        cy = jnp.array([1, 1, 1, 2, 2, 2], jnp.int32)
        cx = x0 + dx
        interior = (cx >= 1) & (cx <= N - 2)
        kinds = jnp.where((dx == 0) & (cy == 1), treasure, border)
        kinds = jnp.where(interior, kinds, C.BOUNDARY).astype(jnp.uint8)
        flat = flat.at[cx * N + cy].set(kinds)
    num_free = 100 - 2 * width
    xs, ys = _free_cell(partial_shuffle(u[:NUM_DRAWS], num_free), col_lo, width)
    cells = xs[:-1] * N + ys[:-1]
    flat = flat.at[cells].set(jnp.asarray(PLACED_KINDS), unique_indices=True)
    pos = jnp.stack([xs[-1], ys[-1]]).astype(jnp.int32)
    return flat.reshape(N, N), pos


def new_state(key: jax.Array, world: str) -> CraftState:
    """A freshly generated world (``world`` static: "plain", "island" or "cave")."""
    grid, pos = generate(key, world)
    return CraftState(
        grid=grid,
        pos=pos,
        direction=jnp.int32(C.DOWN),
        inventory=jnp.zeros(C.NUM_KINDS, jnp.int32),
        step=jnp.int32(0),
    )


def initial_state(key: jax.Array, params: CraftParams, world: str) -> CraftState:
    """The state an episode starts from: a fresh world, or the fixed map if the params hold one."""
    fresh = new_state(key, world)
    fixed = CraftState(
        grid=params.fixed_grid,
        pos=params.fixed_pos,
        direction=params.fixed_direction,
        inventory=jnp.zeros(C.NUM_KINDS, jnp.int32),
        step=jnp.int32(0),
    )
    return select_tree(params.use_fixed_map, fixed, fresh)
