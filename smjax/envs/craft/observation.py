"""Craft observations. All windows are egocentric and ordered [x, y, ...] (x outermost).

``"paper"`` (the reference's 1586 features), dtype **uint8** (values 0/1 except counts):

=============  =====  ===========================================================
indices        size   content
=============  =====  ===========================================================
0 .. 774       775    5 x 5 window one-hot: index ``(dx+2)*155 + (dy+2)*31 + kind`` for
                      the cell at (x+dx, y+dy), dx, dy in -2..2; kind 0 ("invalid" /
                      empty) is never hot; outside the grid is all zeros
775 .. 1549    775    25 x 25 window max-pooled 5 x 5: ``775 + bx*155 + by*31 + kind`` is
                      1 iff ``kind`` occurs in block (bx, by), which covers dx in
                      -12+5bx .. -8+5bx and dy in -12+5by .. -8+5by
1550 .. 1580   31     inventory counts per kind id (clipped to 255)
1581 .. 1584   4      facing one-hot (DOWN, UP, LEFT, RIGHT)
1585           1      constant 1
=============  =====  ===========================================================

The agent's own cell is the window centre (index 2, 2) and reads empty. Nothing is
one-hotted cell by cell: every cell becomes a 31-bit word ``1 << kind`` (empty: 0); the
pooled blocks are ORs of words over x-runs of 5 and then y-runs of 5 (two small dynamic
slices of a padded grid: 300 + 125 word ORs instead of 19,375 one-hot values); the 25 local
and 25 block words are then unpacked to bits in one pass.

``"compact"`` (180 float32):

=============  =====  ===========================================================
0 .. 116       117    3 x 3 window one-hot over the 13 map kinds 0..12 (empty included):
                      ``(dx+1)*39 + (dy+1)*13 + kind``; outside the grid is all zeros
117 .. 149     33     for each of the 11 map kinds 2..12 (workshops 0-2, water, stone,
                      iron, grass, wood, rock, gold, gem): (dx/11, dy/11, present) of the
                      nearest cell of that kind (Manhattan; ties to the lowest x*12+y);
                      zeros when absent. Index ``117 + 3*(kind-2) + {0,1,2}``
150 .. 173     24     inventory counts of the 24 items (kind ids 7..30)
174 .. 177     4      facing one-hot (DOWN, UP, LEFT, RIGHT)
178 .. 179     2      agent position x/11, y/11
=============  =====  ===========================================================

``"none"``: one uint8 zero, for timing the dynamics alone.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core import spaces
from smjax.core.layout import Grid
from smjax.envs.craft import constants as C
from smjax.envs.craft.types import CraftState

N = C.GRID_SIZE
K = C.NUM_KINDS
PAPER_SIZE = 25 * K * 2 + K + 4 + 1
NUM_MAP_KINDS = 13  # kinds 0..12 can be on the grid
COMPACT_SIZE = 9 * NUM_MAP_KINDS + 3 * 11 + len(C.ITEMS) + 4 + 2


def _facing(direction: jax.Array) -> jax.Array:
    return direction == jnp.arange(4)


def _or_reduce(words: jax.Array, axis: int) -> jax.Array:
    # A reduce (rather than chained ``|``) is a fusion root XLA materialises, so the unpack
    # below reads 50 stored words instead of recomputing the gathers and ORs for each of
    # its 1550 output bits.
    return jax.lax.reduce(words, np.uint32(0), jax.lax.bitwise_or, (axis,))


_BIT_SHIFTS = np.arange(K, dtype=np.uint32)


def paper_obs(state: CraftState) -> jax.Array:
    """The reference's 1586 features as uint8 (layout in the module docstring)."""
    x, y = state.pos[0], state.pos[1]
    # Every cell as a kind bit-word; empty (kind 0, the "invalid" slot) sets no bit.
    words = jnp.left_shift(jnp.uint32(1), state.grid.astype(jnp.uint32)) & ~jnp.uint32(1)
    # Local 5 x 5 window: the words themselves (outside the grid: padding, no bits).
    local = jax.lax.dynamic_slice(jnp.pad(words, 2), (x, y), (5, 5))
    # Pooled 25 x 25: OR over x-runs of 5, then over y-runs of 5.
    wx = jax.lax.dynamic_slice(jnp.pad(words, ((12, 12), (0, 0))), (x, 0), (25, N))
    bx = _or_reduce(wx.reshape(5, 5, N), 1)  # [5, N]
    wy = jax.lax.dynamic_slice(jnp.pad(bx, ((0, 0), (12, 12))), (0, y), (5, 25))
    blocks = _or_reduce(wy.reshape(5, 5, 5), 2)  # [5, 5]
    # One unpack of all 50 words to 50 x 31 bits: the first 1550 features in order.
    all_words = jnp.concatenate([local.reshape(-1), blocks.reshape(-1)])
    inventory = jnp.clip(state.inventory, 0, 255).astype(jnp.uint8)
    return jnp.concatenate([
        ((all_words[:, None] >> _BIT_SHIFTS) & np.uint32(1)).astype(jnp.uint8).reshape(-1),
        inventory,
        _facing(state.direction).astype(jnp.uint8),
        jnp.ones(1, jnp.uint8),
    ])


_CELL_X = np.repeat(np.arange(N), N)  # flat index x*12 + y
_CELL_Y = np.tile(np.arange(N), N)
_ABSENT = 1 << 20  # above every distance x 256 + cell key


def compact_obs(state: CraftState) -> jax.Array:
    """A 180-value float32 symbolic observation (layout in the module docstring)."""
    x, y = state.pos[0], state.pos[1]
    local = jax.lax.dynamic_slice(jnp.pad(state.grid, 1, constant_values=255), (x, y), (3, 3))
    local_onehot = local[:, :, None] == jnp.arange(NUM_MAP_KINDS, dtype=jnp.uint8)
    flat = state.grid.reshape(-1)
    dist = jnp.abs(jnp.asarray(_CELL_X) - x) + jnp.abs(jnp.asarray(_CELL_Y) - y)
    kinds = jnp.arange(2, NUM_MAP_KINDS, dtype=jnp.uint8)
    is_kind = flat[None, :] == kinds[:, None]  # [11, 144]
    # The nearest cell of each kind as the min of one integer key, distance x 256 + cell
    # (the lowest cell on ties, as an argmin): a plain min vectorizes on a CPU, where
    # argmin's two-operand reduce does not, and the observation is in every tick.
    scored = jnp.where(is_kind, (dist * 256 + jnp.arange(N * N))[None, :], _ABSENT)
    best = scored.min(axis=1)
    present = best < _ABSENT
    nearest = best & 255
    dx, dy = nearest // N - x, nearest % N - y
    near = jnp.stack([dx / 11.0, dy / 11.0, jnp.ones(11)], axis=1)
    near = jnp.where(present[:, None], near, 0.0)
    return jnp.concatenate([
        local_onehot.reshape(-1).astype(jnp.float32),
        near.reshape(-1).astype(jnp.float32),
        state.inventory[7:].astype(jnp.float32),
        _facing(state.direction).astype(jnp.float32),
        state.pos.astype(jnp.float32) / 11.0,
    ])


def none_obs(state: CraftState) -> jax.Array:
    return jnp.zeros((1,), jnp.uint8)


OBSERVATION_FNS = {"paper": paper_obs, "compact": compact_obs, "none": none_obs}


def observation_layout(kind: str) -> tuple[Grid, ...]:
    """The grids of each observation (docs/environments.md): the paper's 5 x 5 window and
    its 25 x 25 window pooled 5 x 5, each dx-major, then dy, then one channel per kind;
    the compact 3 x 3 window over the 13 map kinds."""
    if kind == "paper":
        return (Grid(0, 5, 5, K), Grid(25 * K, 5, 5, K))
    if kind == "compact":
        return (Grid(0, 3, 3, NUM_MAP_KINDS),)
    return ()


def observation_space(kind: str) -> spaces.Box:
    if kind == "paper":
        return spaces.Box(0, 255, (PAPER_SIZE,), jnp.uint8)
    if kind == "compact":
        return spaces.Box(-1.0, 255.0, (COMPACT_SIZE,), jnp.float32)
    if kind == "none":
        return spaces.Box(0, 0, (1,), jnp.uint8)
    raise ValueError(f"observation must be one of {tuple(OBSERVATION_FNS)}, got {kind!r}")
