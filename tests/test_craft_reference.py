"""A plain-Python model of Craft's rules, hypothesis strategies for Craft states, and the
property tests that hold the JAX dynamics to the model (other test_craft_* files import the
helpers from here)."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from smjax.envs.craft import CraftState, constants as C
from smjax.envs.craft import dynamics

N = C.GRID_SIZE
MAP_GLYPHS = ".........0 1 2~SigwrGE".replace(" ", "")  # empty cells weighted up
DELTAS = {0: (0, -1), 1: (0, 1), 2: (-1, 0), 3: (1, 0)}
RECIPES = [(C.KIND_ID[o], [C.KIND_ID[i] for i in ins], C.WORKSHOPS[w]) for o, ins, w in C.RECIPES]
PRIMS = set(C.PRIMITIVE_IDS)


def py_step(grid, pos, direction, inv, action):
    """Reference rules, written plainly. Returns (grid, pos, direction, inv, fired recipes,
    bridges used)."""
    grid, inv = grid.copy(), inv.copy()
    x, y = pos
    fired, bridges = [], 0
    if action in DELTAS:
        direction = action
        dx, dy = DELTAS[action]
        if grid[x + dx, y + dy] == C.EMPTY:
            x, y = x + dx, y + dy
    elif action == C.USE:
        dx, dy = DELTAS[direction]
        fx, fy = x + dx, y + dy
        kind = int(grid[fx, fy])
        if kind in PRIMS:
            inv[kind] += 1
            grid[fx, fy] = C.EMPTY
        elif kind in C.WORKSHOPS:
            for out, ins, at in RECIPES:
                if at == kind and all(inv[i] >= 1 for i in ins):
                    for i in ins:
                        inv[i] -= 1
                    inv[out] += 1
                    fired.append(out)
        elif kind == C.WATER and inv[C.BRIDGE] > 0:
            inv[C.BRIDGE] -= 1
            grid[fx, fy] = C.EMPTY
            bridges += 1
        elif kind == C.STONE and inv[C.AXE] > 0:
            grid[fx, fy] = C.EMPTY
    return grid, (x, y), direction, inv, fired, bridges


@st.composite
def craft_states(draw, max_inventory: int = 3):
    """Random (grid, pos, direction, inventory) numpy tuples with a boundary ring."""
    grid = np.full((N, N), C.BOUNDARY, np.uint8)
    cells = draw(st.lists(st.sampled_from(MAP_GLYPHS), min_size=100, max_size=100))
    for n, glyph in enumerate(cells):
        grid[1 + n // 10, 1 + n % 10] = C.KIND_OF_GLYPH[glyph]
    x = draw(st.integers(1, N - 2))
    y = draw(st.integers(1, N - 2))
    grid[x, y] = C.EMPTY
    direction = draw(st.integers(0, 3))
    inv = np.zeros(C.NUM_KINDS, np.int32)
    items = draw(st.lists(st.sampled_from(C.ITEMS), max_size=12))
    for item in items:
        inv[C.KIND_ID[item]] = min(inv[C.KIND_ID[item]] + 1, max_inventory)
    return grid, (x, y), direction, inv


def to_state(grid, pos, direction, inv, step=0) -> CraftState:
    return CraftState(
        grid=jnp.asarray(grid, jnp.uint8), pos=jnp.asarray(pos, jnp.int32),
        direction=jnp.int32(direction), inventory=jnp.asarray(inv, jnp.int32),
        step=jnp.int32(step),
    )


def content(kind: int) -> np.ndarray:
    """Primitive content of an item (crafted items: the sum over their inputs)."""
    vec = np.zeros(C.NUM_KINDS, np.int64)
    if kind in PRIMS:
        vec[kind] = 1
    for out, ins, _ in RECIPES:
        if out == kind:
            for i in ins:
                vec += content(i)
    return vec


CONTENT = np.stack([content(k) for k in range(C.NUM_KINDS)])  # [31, 31]


def material(grid, inv) -> np.ndarray:
    """Primitive content of everything on the grid and in the inventory."""
    counts = np.bincount(np.asarray(grid).reshape(-1), minlength=C.NUM_KINDS) + np.asarray(inv)
    return counts @ CONTENT


_transition = jax.jit(dynamics.transition)
_SLOW = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@_SLOW
@given(craft_states(), st.lists(st.integers(0, 5), min_size=1, max_size=25))
def test_jax_dynamics_match_reference_and_conserve_items(start, actions):
    grid, pos, direction, inv = start
    state = to_state(grid, pos, direction, inv)
    initial_material = material(grid, inv)
    bridges_used = 0
    produced = np.zeros(C.NUM_KINDS, np.int64)
    for t, action in enumerate(actions):
        grid_before, inv_before = grid, inv
        grid, pos, direction, inv, fired, bridges = py_step(grid, pos, direction, inv, action)
        bridges_used += bridges
        state = _transition(state, jnp.int32(action))
        np.testing.assert_array_equal(np.asarray(state.grid), grid)
        assert tuple(np.asarray(state.pos)) == pos
        assert int(state.direction) == direction
        np.testing.assert_array_equal(np.asarray(state.inventory), inv)
        assert int(state.step) == t + 1
        # Exact per-kind accounting: grid + inventory change only by pick-ups, recipes
        # (consumed inputs, produced outputs) and removed water/stone.
        change = (np.bincount(grid.reshape(-1), minlength=C.NUM_KINDS) + inv) - (
            np.bincount(grid_before.reshape(-1), minlength=C.NUM_KINDS) + inv_before
        )
        expect = np.zeros(C.NUM_KINDS, np.int64)
        for out in fired:
            ins = next(i for o, i, _ in RECIPES if o == out)
            expect[out] += 1
            expect[ins] -= 1
            produced[out] += 1
        expect[C.BRIDGE] -= bridges
        expect[C.WATER] -= bridges
        removed_stone = (np.sum(grid_before == C.STONE) - np.sum(grid == C.STONE))
        expect[C.STONE] -= removed_stone
        np.testing.assert_array_equal(change[1:], expect[1:])  # kind 0 = empty cells
        # Invariants: the agent stands on an empty cell, the boundary ring is intact.
        x, y = pos
        assert grid[x, y] == C.EMPTY
        ring = np.ones((N, N), bool)
        ring[1:-1, 1:-1] = False
        assert np.all(grid[ring] == C.BOUNDARY)
        assert not np.any(grid[~ring] == C.BOUNDARY)
    # Primitive material is conserved, except what crossing water destroyed with a bridge.
    final = material(grid, inv) + bridges_used * CONTENT[C.BRIDGE]
    np.testing.assert_array_equal(final, initial_material)


@_SLOW
@given(craft_states(), st.integers(0, 5))
def test_vmapped_transition_equals_unbatched(start, action):
    grid, pos, direction, inv = start
    states = [to_state(grid, pos, d, inv) for d in range(4)]
    batch = jax.tree.map(lambda *xs: jnp.stack(xs), *states)
    out = jax.jit(jax.vmap(dynamics.transition))(batch, jnp.full(4, action, jnp.int32))
    for d, single in enumerate(states):
        expect = _transition(single, jnp.int32(action))
        for a, b in zip(jax.tree.leaves(expect), jax.tree.leaves(out)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b)[d])
