"""Registry, overrides and their errors, ASCII I/O, rendering, GIFs and determinism."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

import smjax
from smjax.envs.craft import (
    REFERENCE_GEM_MAP, REFERENCE_GOLD_MAP, CraftEnv, constants as C, from_ascii, inventory_dict,
    to_ascii,
)
from smjax.viz import write_gif

N = C.GRID_SIZE
INTERIOR_GLYPHS = ".0 1 2~SigwrGE".replace(" ", "")


def test_all_24_tasks_registered():
    names = [n for n in smjax.registry() if n.startswith("craft/")]
    expect = {f"craft/get_{p}" for p in C.PRIMITIVES} | {f"craft/make_{c}" for c in C.CRAFTED}
    assert set(names) == expect and len(names) == 24
    env, params = smjax.make("craft/make_slingshot")
    assert isinstance(env, CraftEnv) and env.name == "craft/make_slingshot"
    assert int(params.goal) == C.KIND_ID["slingshot"]
    assert env.primitive_action_names == ("down", "up", "left", "right", "use")
    assert env.action_space(params).n == 5


def test_bad_names_and_overrides_raise_clear_errors():
    with pytest.raises(KeyError, match="craft/get_gem"):
        smjax.make("craft/get_diamond")
    with pytest.raises(TypeError, match="observation"):
        smjax.make("craft/get_gem", obs="paper")
    with pytest.raises(ValueError, match="observation.*paper"):
        smjax.make("craft/get_gem", observation="pixels")
    with pytest.raises(ValueError, match="max_steps"):
        smjax.make("craft/get_gem", max_steps=0)
    with pytest.raises(ValueError, match="max_steps"):
        smjax.make("craft/get_gem", max_steps=2.5)
    with pytest.raises(ValueError, match="map_seed"):
        smjax.make("craft/get_gem", map_seed=-1)
    with pytest.raises(ValueError, match="fixed_map"):  # booleans take their words only
        smjax.make("craft/get_gem", fixed_map="maybe")
    with pytest.raises(ValueError, match="unknown craft task"):
        from_ascii(REFERENCE_GOLD_MAP, task="get_diamond")
    env, params = smjax.make("craft/get_gem", max_steps=17)
    assert int(params.max_steps) == 17


def test_reference_maps_load():
    state, params = from_ascii(REFERENCE_GOLD_MAP, task="get_gold")
    assert tuple(np.asarray(state.pos)) == (8, 4) and int(state.direction) == C.DOWN
    assert int(state.grid[6, 1]) == C.GOLD and int(state.grid[6, 2]) == C.WATER
    assert int(state.grid[5, 6]) == C.WORKSHOPS[2]  # '2' in text row 5 -> y = 6
    assert to_ascii(state) == REFERENCE_GOLD_MAP
    gem, _ = from_ascii(REFERENCE_GEM_MAP, task="get_gem")
    assert int(gem.grid[6, 1]) == C.GEM and int(gem.grid[5, 1]) == C.STONE
    # A reset with the returned params restores the map.
    env, _ = smjax.make("craft/get_gold")
    _, again = env.reset(jax.random.PRNGKey(3), params)
    assert to_ascii(again) == REFERENCE_GOLD_MAP


@st.composite
def ascii_maps(draw):
    cells = draw(st.lists(st.sampled_from(INTERIOR_GLYPHS), min_size=100, max_size=100))
    agent = draw(st.integers(0, 99))
    cells[agent] = "@"
    # make_axe's raw materials, without which from_ascii refuses the map as unsolvable
    cells[(agent + 1) % 100], cells[(agent + 2) % 100] = "w", "i"
    rows = ["#" * N] + ["#" + "".join(cells[r * 10:(r + 1) * 10]) + "#" for r in range(10)]
    return "\n".join(rows + ["#" * N])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ascii_maps())
def test_ascii_round_trip(text):
    state, _ = from_ascii(text, task="make_axe")
    assert to_ascii(state) == text
    assert from_ascii("\n\n  " + text.replace("\n", "\n  ") + "\n", task="make_axe")[0].grid.shape \
        == (N, N)


def _replace_cell(row: int, col: int, glyph: str) -> str:
    rows = REFERENCE_GOLD_MAP.split("\n")
    rows[row] = rows[row][:col] + glyph + rows[row][col + 1:]
    return "\n".join(rows)


@pytest.mark.parametrize("text,pattern", [
    (REFERENCE_GOLD_MAP + "\n############", "12 rows, got 13"),
    (REFERENCE_GOLD_MAP.replace("#r.....i...#", "#r.....i....#"), "row 2 must have 12 columns"),
    (_replace_cell(3, 4, "x"), "unknown glyph 'x' at row 3, column 4"),
    (REFERENCE_GOLD_MAP.replace("@", "."), "exactly one agent.*found 0"),
    (_replace_cell(1, 1, "@"), "found 2 .*row 1 column 1.*row 7 column 8"),
    (_replace_cell(0, 5, "."), "row 0, column 5 .* must be '#'"),
    (_replace_cell(4, 3, "#"), "row 4, column 3 .* may not be '#'"),
    (_replace_cell(11, 0, "@"), "row 11, column 0"),
])
def test_malformed_ascii_names_row_and_column(text, pattern):
    with pytest.raises(ValueError, match=pattern):
        from_ascii(text)


def test_inventory_dict():
    state, _ = from_ascii(REFERENCE_GOLD_MAP, task="get_gold")
    assert inventory_dict(state) == {}
    inv = state.inventory.at[C.KIND_ID["wood"]].set(2).at[C.KIND_ID["axe"]].set(1)
    assert inventory_dict(state.replace(inventory=inv)) == {"wood": 2, "axe": 1}
    env, params = smjax.make("craft/get_gem")
    _, batch = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(0), 2),
                                                       params)
    with pytest.raises(ValueError, match="unbatched"):
        inventory_dict(batch)


def test_render_and_gif(tmp_path):
    env, params = smjax.make("craft/get_gold")
    state, _ = from_ascii(REFERENCE_GOLD_MAP, task="get_gold")
    inv = state.inventory.at[C.KIND_ID["wood"]].set(3).at[C.KIND_ID["bridge"]].set(1)
    state = state.replace(inventory=inv)
    image = env.render(state, params)
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    assert image.shape[0] > image.shape[1] >= 12 * 8  # map plus inventory strip
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10
    # A different facing draws a different agent; a jitted state renders the same.
    turned = env.render(state.replace(direction=jnp.int32(C.UP)), params)
    assert not np.array_equal(turned, image)
    jitted = jax.jit(lambda s: s)(state)
    np.testing.assert_array_equal(env.render(jitted, params), image)
    frames = [image, turned, image]
    path = write_gif(frames, tmp_path / "craft.gif", fps=4)
    with Image.open(path) as gif:
        assert gif.n_frames == 3 and gif.size == (image.shape[1], image.shape[0])
    with pytest.raises(ValueError, match="frame 1"):
        write_gif([image, image[:10]], tmp_path / "bad.gif")
    with pytest.raises(ValueError, match="at least one frame"):
        write_gif([], tmp_path / "empty.gif")


# vmapped batch == unbatched runs, auto-reset and final_observation: test_env_contract.py
# checks them with smjax.testing.check_env (craft/get_wood, max_steps=3, paper observation).


def test_fixed_key_gives_identical_trajectories():
    env, params = smjax.make("craft/make_stick", observation="compact")

    def run(key):
        obs, state = env.reset(key, params)

        def body(carry, k):
            state = carry
            a = jax.random.randint(k, (), 0, 5)
            obs, state, reward, *_ = env.step(k, state, a, params)
            return state, (obs, reward)
        return jax.lax.scan(body, state, jax.random.split(key, 50))

    run = jax.jit(run)
    a, b = run(jax.random.PRNGKey(4)), run(jax.random.PRNGKey(4))
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    c = run(jax.random.PRNGKey(5))
    assert not np.array_equal(np.asarray(a[1][0]), np.asarray(c[1][0]))


def test_bench_measures_a_tiny_run():
    from smjax.envs.craft.bench import measure

    out = measure("make_stick", "none", num_envs=2, steps=3, repeats=1)
    assert out["num_envs"] == 2 and out["steps"] == 3 and out["steps_per_second"] > 0
