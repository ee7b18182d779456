"""Hostile-input fuzzing: malformed maps, hierarchies and configs fail with the library's own
error types (never a stray TypeError/IndexError), and environments keep their invariants and
finite observations under long random play.

The big step counts (Craft 4096 x 250 = ~1e6 steps, football 1024 x 1000) are ``slow``; the
default run plays smaller batches of the same checks.
"""
from __future__ import annotations

import json
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import smjax
from hier_env import KeyDoor
from smjax.envs.craft import constants as C
from smjax.envs.craft import REFERENCE_GEM_MAP, from_ascii, to_ascii
from smjax.envs.football import constants as FC
from smjax.options import HierarchyError, declare
from smjax.train.config import ConfigError, TrainConfig

N = C.GRID_SIZE
GLYPHS = "".join(C.KIND_OF_GLYPH) + C.AGENT_GLYPH
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ---------------------------------------------------------------- (a) Craft ASCII maps
def _check_map_outcome(text) -> None:
    """from_ascii returns a valid fixed map or raises ValueError; nothing else."""
    try:
        state, params = from_ascii(text)
    except ValueError:
        return
    grid = np.asarray(state.grid)
    ring = np.ones((N, N), bool)
    ring[1:-1, 1:-1] = False
    assert np.all(grid[ring] == C.BOUNDARY) and np.all(grid[~ring] != C.BOUNDARY)
    x, y = np.asarray(state.pos)
    assert grid[x, y] == C.EMPTY
    assert bool(params.use_fixed_map)
    assert from_ascii(to_ascii(state))[0].grid.tolist() == grid.tolist()  # round trip


@given(text=st.one_of(st.text(max_size=300), st.text(alphabet=GLYPHS + "\n \t\r", max_size=200)))
@FUZZ
def test_random_text_is_a_map_or_a_value_error(text):
    _check_map_outcome(text)


@given(rows=st.integers(0, 15), cols=st.integers(0, 15), data=st.data())
@FUZZ
def test_random_glyph_grids_of_any_size(rows, cols, data):
    grid = data.draw(st.lists(st.text(alphabet=GLYPHS, min_size=cols, max_size=cols),
                              min_size=rows, max_size=rows))
    _check_map_outcome("\n".join(grid))


@given(data=st.data())
@FUZZ
def test_mutated_reference_map(data):
    # Near-valid maps reach the deepest checks (ring, agent count) more often than random text.
    rows = [list(r) for r in REFERENCE_GEM_MAP.split("\n")]
    for _ in range(data.draw(st.integers(0, 4))):
        r, c = data.draw(st.integers(0, N - 1)), data.draw(st.integers(0, N - 1))
        rows[r][c] = data.draw(st.sampled_from(GLYPHS + "x ?"))
    _check_map_outcome("\n".join("".join(r) for r in rows))


@pytest.mark.parametrize("bad", [None, 12, b"#" * 12, ["############"] * 12, 1.5])
def test_non_text_maps_raise_value_error(bad):
    with pytest.raises(ValueError, match="string"):
        from_ascii(bad)


def test_reference_map_round_trips():
    state, _ = from_ascii(REFERENCE_GEM_MAP)
    assert to_ascii(state) == REFERENCE_GEM_MAP


# ---------------------------------------------------------------- (b) hierarchy declarations
KD = KeyDoor()
NAMES = ["open_door", "give_key", "reach_door", "left", "right", "use", "primitives", "", "nope"]
name_or_junk = st.one_of(st.sampled_from(NAMES), st.text(max_size=6), st.integers(), st.none(),
                         st.lists(st.sampled_from(NAMES), max_size=2))
kids = st.one_of(st.lists(name_or_junk, max_size=5), st.tuples(st.sampled_from(NAMES)),
                 st.sampled_from(NAMES), st.integers(), st.none(),
                 st.dictionaries(st.sampled_from(NAMES), st.integers(), max_size=2))
children = st.dictionaries(st.one_of(st.sampled_from(NAMES), st.text(max_size=5), st.integers()),
                           kids, max_size=5)


@given(task=st.one_of(st.sampled_from(NAMES), st.integers(), st.none()), spec=children)
@FUZZ
def test_random_declarations_build_or_raise_hierarchy_error(task, spec):
    try:
        h = declare(KD, task, spec)
    except HierarchyError as err:
        assert str(err)  # the message names the culprit; never empty
        return
    # A hierarchy that builds is coherent: every option reachable, masks match children.
    assert h.option_names[0] == task and h.num_options == len(set(h.option_names))
    assert h.child_mask().sum() == sum(len(h.children.get(n, ())) for n in h.option_names)
    for name in h.option_names[1:]:
        assert h.templates[name].realisable


@given(order=st.permutations(["give_key", "reach_door"]))
@settings(max_examples=4, deadline=None)
def test_cycles_are_named(order):
    a, b = order
    with pytest.raises(HierarchyError, match="cycle"):
        declare(KD, "open_door", {"open_door": [a], a: [b], b: [a, "use"]})


# ---------------------------------------------------------------- (c) training configs
FIELDS = sorted(TrainConfig.__dataclass_fields__)
json_value = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**20), st.floats(allow_nan=True),
              st.text(max_size=8), st.sampled_from(["top-down", "flat", "ppo", "dqn", "greedy"])),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=3)),
    max_leaves=6)
config_dicts = st.dictionaries(st.one_of(st.sampled_from(FIELDS), st.text(max_size=8), st.integers()),
                               json_value, max_size=6)


@given(data=config_dicts)
@FUZZ
def test_random_config_dicts_build_or_raise_config_error(data):
    try:
        cfg = TrainConfig.from_dict(data)
    except ConfigError as err:
        assert isinstance(err, ValueError) and str(err)
        return
    assert repr(TrainConfig.from_dict(cfg.to_dict()).to_dict()) == repr(cfg.to_dict())


@given(body=st.one_of(st.text(max_size=120), config_dicts.map(lambda d: json.dumps({str(k): v for k, v in d.items()})),
                      st.binary(max_size=60)),
       suffix=st.sampled_from([".json", ".yaml", ".yml", ".txt"]))
@settings(max_examples=120, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_random_config_files_build_or_raise_config_error(tmp_path, body, suffix):
    path = tmp_path / f"cfg{suffix}"
    if isinstance(body, bytes):
        path.write_bytes(body)
    else:
        path.write_text(body)
    try:
        TrainConfig.from_file(path)
    except ConfigError as err:
        assert str(err)


# ---------------------------------------------------------------- (d) long random play
def _craft_play(num_envs: int, ticks: int, seed: int = 0):
    # A short step cap so that auto-reset (and fresh world generation) runs many times.
    env, params = smjax.make("craft/get_gem", observation="compact", max_steps=60)
    ring = np.ones((N, N), bool)
    ring[1:-1, 1:-1] = False
    ring = jnp.asarray(ring)

    def checks(state, obs):
        grid = state.grid
        x, y = state.pos[:, 0], state.pos[:, 1]
        on_cell = grid[jnp.arange(num_envs), x, y]
        return jnp.stack([
            jnp.all(jnp.where(ring, grid == C.BOUNDARY, grid != C.BOUNDARY)),
            jnp.all(on_cell == C.EMPTY),
            jnp.all((x >= 1) & (x <= N - 2) & (y >= 1) & (y <= N - 2)),
            jnp.all(state.inventory >= 0),
            jnp.all((state.direction >= 0) & (state.direction < 4)),
            jnp.all(jnp.isfinite(obs)),
            jnp.all((obs[:, :117] == 0) | (obs[:, :117] == 1)),   # local one-hot window
            jnp.all(jnp.abs(obs[:, 117:150]) <= 1.0),             # (dx/11, dy/11, present)
            jnp.all(obs[:, 150:174] >= 0),                        # inventory counts
            jnp.all((obs[:, 178:] >= 0) & (obs[:, 178:] <= 1)),   # position / 11
        ])

    @jax.jit
    def play(key):
        obs, state = jax.vmap(env.reset, (0, None))(jax.random.split(key, num_envs), params)

        def body(carry, k):
            state, obs = carry
            k_act, k_step = jax.random.split(k)
            actions = jax.random.randint(k_act, (num_envs,), 0, env.action_space(params).n)
            obs, state, reward, term, trunc, info = jax.vmap(env.step, (0, 0, 0, None))(
                jax.random.split(k_step, num_envs), state, actions, params)
            ok = checks(state, obs) & jnp.all(jnp.isfinite(info["final_observation"]))
            return (state, obs), (ok, jnp.sum(term | trunc))

        _, (ok, terms) = jax.lax.scan(body, (state, obs), jax.random.split(key, ticks))
        return checks(state, obs), ok, terms

    return play(jax.random.PRNGKey(seed))


CRAFT_CHECKS = ["ring", "agent on empty", "agent interior", "inventory >= 0", "facing", "obs finite",
                "one-hot", "nearest in [-1, 1]", "counts >= 0", "position in [0, 1]"]


def _assert_craft(result):
    first, ok, _ = result
    bad = [CRAFT_CHECKS[i] for i in np.flatnonzero(~np.asarray(ok).all(0) | ~np.asarray(first))]
    assert not bad, f"invariants broken: {bad}"


def test_craft_invariants_under_random_play():
    result = _craft_play(256, 130)
    _assert_craft(result)
    assert int(np.asarray(result[2]).sum()) >= 256 * 2


@pytest.mark.slow
def test_craft_invariants_million_steps():
    result = _craft_play(4096, 250, seed=1)
    _assert_craft(result)
    assert int(np.asarray(result[2]).sum()) > 4096 * 3  # every env auto-reset several times


def _football_play(num_envs: int, ticks: int, seed: int = 0):
    env, params = smjax.make("football/11v11_medium", game_length=400)
    space = env.action_space(params)

    @jax.jit
    def play(key):
        obs, state = jax.vmap(env.reset, (0, None))(jax.random.split(key, num_envs), params)

        def body(state, k):
            k_act, k_step = jax.random.split(k)
            actions = jax.random.randint(k_act, (num_envs,) + space.shape, 0, space.n)
            obs, state, reward, term, trunc, info = jax.vmap(env.step, (0, 0, 0, None))(
                jax.random.split(k_step, num_envs), state, actions, params)
            ok = jnp.stack([
                jnp.all(jnp.isfinite(state.pos)) & jnp.all(jnp.isfinite(state.ball_pos)),
                jnp.all(jnp.abs(state.pos[..., 0]) <= FC.PLAYER_BOUND_X + 1e-5),
                jnp.all(jnp.abs(state.pos[..., 1]) <= FC.PLAYER_BOUND_Y + 1e-5),
                jnp.all(jnp.abs(state.ball_pos[:, :2]) <= 2.0) & jnp.all(state.ball_pos[:, 2] >= 0),
                jnp.all(state.score >= 0) & jnp.all(info["score"] >= 0),
                jnp.all(jnp.isfinite(obs)) & jnp.all(jnp.isfinite(reward)),
                jnp.all((state.owner >= -1) & (state.owner < 22)),
            ])
            return state, (ok, jnp.sum(info["goals"]))

        _, (ok, goals) = jax.lax.scan(body, state, jax.random.split(key, ticks))
        return ok, goals

    return play(jax.random.PRNGKey(seed))


FOOTBALL_CHECKS = ["finite", "x in box", "y in box", "ball in box", "score >= 0", "obs finite", "owner"]


def _assert_football(result):
    ok, _ = result
    bad = [FOOTBALL_CHECKS[i] for i in np.flatnonzero(~np.asarray(ok).all(0))]
    assert not bad, f"invariants broken: {bad}"


def test_football_invariants_under_random_play():
    _assert_football(_football_play(64, 200))


@pytest.mark.slow
def test_football_invariants_long_play():
    _assert_football(_football_play(1024, 1000, seed=1))
