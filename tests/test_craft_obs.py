"""Observations: the fast paper features equal a plain one-hot-then-max-pool version."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import chex
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import HealthCheck, given, settings

import smjax
from smjax.envs.craft import constants as C
from smjax.envs.craft import observation as O
from test_craft_reference import craft_states, to_state

N = C.GRID_SIZE
K = C.NUM_KINDS


def naive_paper_obs(grid, pos, direction, inv) -> np.ndarray:
    """The reference's features written plainly: one-hot windows, then a 5 x 5 max-pool."""
    x, y = pos

    def window(size):
        half = size // 2
        out = np.zeros((size, size, K), np.uint8)
        for i in range(size):
            for j in range(size):
                cx, cy = x - half + i, y - half + j
                if 0 <= cx < N and 0 <= cy < N and grid[cx, cy] != C.EMPTY:
                    out[i, j, grid[cx, cy]] = 1
        return out

    local = window(5)
    big = window(25)
    pooled = big.reshape(5, 5, 5, 5, K).max(axis=(1, 3))
    facing = np.zeros(4, np.uint8)
    facing[direction] = 1
    return np.concatenate([local.ravel(), pooled.ravel(), np.clip(inv, 0, 255).astype(np.uint8),
                           facing, [1]]).astype(np.uint8)


def naive_compact_obs(grid, pos, direction, inv) -> np.ndarray:
    x, y = pos
    local = np.zeros((3, 3, O.NUM_MAP_KINDS), np.float32)
    for i in range(3):
        for j in range(3):
            cx, cy = x - 1 + i, y - 1 + j
            if 0 <= cx < N and 0 <= cy < N:
                local[i, j, grid[cx, cy]] = 1
    near = np.zeros((11, 3), np.float32)
    for n, kind in enumerate(range(2, 13)):
        cells = [(abs(cx - x) + abs(cy - y), cx * N + cy, cx, cy)
                 for cx in range(N) for cy in range(N) if grid[cx, cy] == kind]
        if cells:
            _, _, cx, cy = min(cells)
            near[n] = ((cx - x) / 11, (cy - y) / 11, 1)
    facing = np.zeros(4, np.float32)
    facing[direction] = 1
    return np.concatenate([local.ravel(), near.ravel(), inv[7:].astype(np.float32), facing,
                           np.array([x, y], np.float32) / 11])


_paper = jax.jit(O.paper_obs)
_compact = jax.jit(O.compact_obs)
_SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@_SETTINGS
@given(craft_states(max_inventory=300))
def test_paper_obs_equals_naive_reference(start):
    grid, pos, direction, inv = start
    got = np.asarray(_paper(to_state(grid, pos, direction, inv)))
    assert got.shape == (1586,) and got.dtype == np.uint8
    np.testing.assert_array_equal(got, naive_paper_obs(grid, pos, direction, inv))


@_SETTINGS
@given(craft_states())
def test_compact_obs_equals_naive_reference(start):
    grid, pos, direction, inv = start
    got = np.asarray(_compact(to_state(grid, pos, direction, inv)))
    assert got.shape == (O.COMPACT_SIZE,) and O.COMPACT_SIZE < 300
    np.testing.assert_allclose(got, naive_compact_obs(grid, pos, direction, inv), atol=1e-6)


def test_paper_obs_on_generated_worlds_and_block_semantics():
    env, params = smjax.make("craft/get_gem")
    keys = jax.random.split(jax.random.PRNGKey(0), 32)
    obs, states = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    chex.assert_shape(obs, (32, 1586))
    chex.assert_type(obs, jnp.uint8)
    for i in range(32):
        s = jax.tree.map(lambda a: np.asarray(a[i]), states)
        np.testing.assert_array_equal(
            np.asarray(obs[i]), naive_paper_obs(s.grid, tuple(s.pos), int(s.direction),
                                                s.inventory))
    # Every kind on the map shows up in some pooled block (the 25 x 25 window covers the
    # whole 12 x 12 grid from any interior cell); the "invalid" slot 0 never does.
    pooled = np.asarray(obs[0, 775:1550]).reshape(25, K)
    on_map = set(np.unique(np.asarray(states.grid[0]))) - {C.EMPTY}
    assert set(np.nonzero(pooled.any(axis=0))[0]) == on_map
    assert np.asarray(obs[:, :1550]).reshape(32, 50, K)[:, :, 0].sum() == 0
    assert np.all(np.asarray(obs[:, -1]) == 1)


def test_observation_spaces_and_none():
    for kind, shape, dtype in (("paper", (1586,), jnp.uint8),
                               ("compact", (O.COMPACT_SIZE,), jnp.float32),
                               ("none", (1,), jnp.uint8)):
        env, params = smjax.make("craft/make_axe", observation=kind)
        obs, state = env.reset(jax.random.PRNGKey(1), params)
        space = env.observation_space(params)
        assert space.shape == shape == obs.shape and obs.dtype == dtype
        assert bool(space.contains(obs))
        chex.assert_tree_all_finite(obs.astype(jnp.float32))
        obs2, *_ = env.step(jax.random.PRNGKey(2), state, jnp.int32(4), params)
        assert obs2.shape == shape


@_SETTINGS
@given(craft_states(max_inventory=3))
def test_declared_grids_are_the_observations_windows(start):
    # Environment.observation_layout: each declared grid, reshaped (height, width, kind),
    # holds at [i, j] the cell (x - half + i, y - half + j) around the agent
    grid, pos, direction, inv = start
    state = to_state(grid, pos, direction, inv)
    x, y = pos
    for kind, fn, windows in (("paper", _paper, [(5, 1), (25, 5)]), ("compact", _compact, [(3, 1)])):
        obs = np.asarray(fn(state))
        layout = O.observation_layout(kind)
        assert len(layout) == len(windows)
        for g, (size, pool) in zip(layout, windows):
            cells = obs[g.start:g.stop].reshape(g.height, g.width, g.channels)
            assert (g.height, g.width) == (size // pool, size // pool)
            for i in range(size):
                for j in range(size):
                    cx, cy = x - size // 2 + i, y - size // 2 + j
                    inside = 0 <= cx < N and 0 <= cy < N
                    if inside and (kind == "compact" or grid[cx, cy] != C.EMPTY):
                        assert cells[i // pool, j // pool, grid[cx, cy]] == 1
    assert O.observation_layout("none") == ()
