"""Craft rules through the public env: recipes and multi-fire order, water/stone, blocked
moves, reward penalty, step caps and auto-reset."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from smjax.envs.craft import constants as C
from smjax.envs.craft import from_ascii, inventory_dict
from test_craft_reference import py_step

DOWN, UP, LEFT, RIGHT, USE, NOOP = range(6)

# Agent at (5, 5) facing DOWN looks at (5, 4): the cell X below. The task's goal item (a
# gem by default) sits in the far corner (10, 10), out of every test's one-step reach:
# from_ascii refuses a get_X map without any X.
def one_cell_map(glyph: str, corner: str = "E") -> str:
    rows = ["############", f"#.........{corner}#"] + ["#..........#"] * 9 + ["############"]
    rows[11 - 5] = "#....@.....#"
    rows[11 - 4] = "#...." + glyph + ".....#"
    return "\n".join(rows)


ENV, _ = smjax.make("craft/get_gem", observation="none")
STEP = jax.jit(ENV.step_env)


def with_inventory(state, items: dict[str, int]):
    inv = np.zeros(C.NUM_KINDS, np.int32)
    for name, count in items.items():
        inv[C.KIND_ID[name]] = count
    return state.replace(inventory=jnp.asarray(inv))


def use_on(glyph: str, items: dict[str, int], task: str = "get_gem"):
    goal = C.TASKS[task]
    corner = C.GLYPH_OF_KIND[C.KIND_ID[goal]] if goal in C.PRIMITIVES else "E"
    state, params = from_ascii(one_cell_map(glyph, corner), task=task)
    state = with_inventory(state, items)
    _, state, reward, term, trunc, _ = STEP(jax.random.PRNGKey(0), state, jnp.int32(USE), params)
    return state, float(reward), bool(term), bool(trunc)


@pytest.mark.parametrize("output,inputs,workshop", C.RECIPES)
def test_each_recipe_consumes_inputs_and_yields_one(output, inputs, workshop):
    # 4 of each input: earlier recipes of the same workshop may take one each (multi-fire),
    # so the recipe under test still finds its inputs.
    held = {i: 4 for i in inputs}
    state, *_ = use_on(str(workshop), held)
    inv = np.zeros(C.NUM_KINDS, np.int32)
    for name, count in held.items():
        inv[C.KIND_ID[name]] = count
    grid = np.full((12, 12), C.BOUNDARY, np.uint8)
    grid[1:-1, 1:-1] = C.EMPTY
    grid[5, 4] = C.WORKSHOPS[workshop]
    _, _, _, expect, fired, _ = py_step(grid, (5, 5), DOWN, inv, USE)
    assert C.KIND_ID[output] in fired
    np.testing.assert_array_equal(np.asarray(state.inventory), expect)
    assert inventory_dict(state).get(output, 0) >= 1
    for i in inputs:  # this recipe (and maybe earlier ones) consumed one of each input
        assert inventory_dict(state).get(i, 0) <= 3
    # The workshop stays, the agent does not move.
    assert int(state.grid[5, 4]) == C.WORKSHOPS[workshop]
    assert tuple(np.asarray(state.pos)) == (5, 5)


def test_single_input_recipes_yield_exactly_one():
    for out, inputs, workshop in (("plank", "wood", 0), ("cloth", "grass", 2),
                                  ("rope", "grass", 0), ("stick", "wood", 1)):
        state, *_ = use_on(str(workshop), {inputs: 1})
        assert inventory_dict(state) == {out: 1}


def test_recipe_needs_all_inputs_and_the_right_workshop():
    state, *_ = use_on("2", {"wood": 1})  # bridge needs iron too; wood alone fires nothing @2
    assert inventory_dict(state) == {"wood": 1}
    state, *_ = use_on("0", {"iron": 1, "rock": 1})  # knife is made at workshop2, not 0
    assert inventory_dict(state) == {"iron": 1, "rock": 1}


def test_multi_fire_runs_in_file_order_on_the_running_inventory():
    # workshop1: stick{wood} fires before bundle{wood,grass}, so the wood goes to the stick.
    state, *_ = use_on("1", {"wood": 1, "grass": 1})
    assert inventory_dict(state) == {"stick": 1, "grass": 1}
    # The stick just made is seen by the later shears{stick,iron} in the same USE.
    state, *_ = use_on("1", {"wood": 1, "iron": 1})
    assert inventory_dict(state) == {"shears": 1}
    # workshop0: plank, rope fire; hammer{wood,rock} finds no wood left.
    state, *_ = use_on("0", {"wood": 1, "grass": 1, "rock": 1})
    assert inventory_dict(state) == {"plank": 1, "rope": 1, "rock": 1}
    # Each recipe fires at most once per USE even with plenty of input.
    state, *_ = use_on("0", {"wood": 3})
    assert inventory_dict(state) == {"plank": 1, "wood": 2}


def test_pick_up_every_primitive():
    for glyph, name in (("i", "iron"), ("g", "grass"), ("w", "wood"), ("r", "rock"),
                        ("G", "gold"), ("E", "gem")):
        state, *_ = use_on(glyph, {})
        assert inventory_dict(state) == {name: 1}
        assert int(state.grid[5, 4]) == C.EMPTY


def test_water_needs_a_bridge_which_is_consumed():
    state, *_ = use_on("~", {})
    assert int(state.grid[5, 4]) == C.WATER and inventory_dict(state) == {}
    state, *_ = use_on("~", {"bridge": 2})
    assert int(state.grid[5, 4]) == C.EMPTY and inventory_dict(state) == {"bridge": 1}


def test_stone_needs_an_axe_which_is_kept():
    state, *_ = use_on("S", {"bridge": 1})
    assert int(state.grid[5, 4]) == C.STONE
    state, *_ = use_on("S", {"axe": 1})
    assert int(state.grid[5, 4]) == C.EMPTY and inventory_dict(state) == {"axe": 1}


def test_use_on_empty_or_boundary_does_nothing():
    state, *_ = use_on(".", {"wood": 1})
    assert inventory_dict(state) == {"wood": 1}
    text = one_cell_map(".").split("\n")
    text[11 - 5], text[11 - 1] = "#..........#", "#....@.....#"  # agent at (5, 1), wall below
    state, params = from_ascii("\n".join(text))
    _, after, *_ = STEP(jax.random.PRNGKey(0), state, jnp.int32(USE), params)
    np.testing.assert_array_equal(np.asarray(after.grid), np.asarray(state.grid))


@pytest.mark.parametrize("glyph", list("#012~SigwrGE"))
def test_moving_into_an_occupied_cell_is_blocked_but_turns(glyph):
    if glyph == "#":
        text = one_cell_map(".").split("\n")
        text[11 - 5], text[11 - 1] = "#..........#", "#....@.....#"
        state, params = from_ascii("\n".join(text))
        start = (5, 1)
    else:
        state, params = from_ascii(one_cell_map(glyph))
        start = (5, 5)
    state = state.replace(direction=jnp.int32(UP))
    _, after, *_ = STEP(jax.random.PRNGKey(0), state, jnp.int32(DOWN), params)
    assert tuple(np.asarray(after.pos)) == start
    assert int(after.direction) == DOWN


def test_moves_follow_the_coordinate_convention():
    state, params = from_ascii(one_cell_map("."))
    for action, expect in ((DOWN, (5, 4)), (UP, (5, 6)), (LEFT, (4, 5)), (RIGHT, (6, 5))):
        _, after, *_ = STEP(jax.random.PRNGKey(0), state, jnp.int32(action), params)
        assert tuple(np.asarray(after.pos)) == expect and int(after.direction) == action
    _, after, *_ = STEP(jax.random.PRNGKey(0), state, jnp.int32(NOOP), params)
    assert tuple(np.asarray(after.pos)) == (5, 5) and int(after.step) == 1


def test_reward_penalises_other_items_and_terminates_on_goal():
    # Goal wood: picking it up with nothing else held pays 1.
    _, reward, term, trunc = use_on("w", {}, task="get_wood")
    assert reward == pytest.approx(1.0) and term and not trunc
    # Other items cost 0.1 per unit (multiplicity counts); extra goal units are free.
    _, reward, term, _ = use_on("w", {"stick": 2, "iron": 1, "wood": 3}, task="get_wood")
    assert reward == pytest.approx(0.7) and term
    _, reward, term, _ = use_on("w", {"stick": 11}, task="get_wood")
    assert reward == 0.0 and term
    # Without the goal: no reward, not terminated.
    _, reward, term, _ = use_on("i", {}, task="get_wood")
    assert reward == 0.0 and not term


def test_reference_step_caps():
    caps = {"get_wood": 100, "get_iron": 100, "make_stick": 200, "make_bridge": 300,
            "make_axe": 400, "get_gold": 400, "get_gem": 500}
    for task, cap in caps.items():
        _, params = smjax.make(f"craft/{task}")
        assert int(params.max_steps) == cap
    for task in C.TASKS:
        _, params = smjax.make(f"craft/{task}")
        assert 100 <= int(params.max_steps) <= 700


def test_truncation_at_cap_and_auto_reset_with_final_observation():
    env, _ = smjax.make("craft/get_gem", observation="paper")
    state, params = from_ascii(one_cell_map("."), task="get_gem", max_steps=3)
    step = jax.jit(env.step)
    key = jax.random.PRNGKey(3)
    for t in range(3):
        obs, state, reward, term, trunc, info = step(key, state, jnp.int32(LEFT), params)
        if t < 2:
            assert not bool(trunc) and int(state.step) == t + 1
            np.testing.assert_array_equal(np.asarray(info["final_observation"]), np.asarray(obs))
    assert bool(trunc) and not bool(term)
    # Auto-reset restored the fixed map; the final observation is of the pre-reset state.
    assert int(state.step) == 0 and tuple(np.asarray(state.pos)) == (5, 5)
    pre_reset = env.get_obs(state.replace(pos=jnp.array([2, 5], jnp.int32),
                                          direction=jnp.int32(LEFT), step=jnp.int32(3)), params)
    np.testing.assert_array_equal(np.asarray(info["final_observation"]), np.asarray(pre_reset))
    np.testing.assert_array_equal(np.asarray(obs), np.asarray(env.get_obs(state, params)))


def test_termination_triggers_auto_reset():
    env, _ = smjax.make("craft/get_wood", observation="none")
    state, params = from_ascii(one_cell_map("w"), task="get_wood")
    _, after, reward, term, _, _ = jax.jit(env.step)(jax.random.PRNGKey(0), state,
                                                     jnp.int32(USE), params)
    assert bool(term) and float(reward) == 1.0
    assert inventory_dict(after) == {} and int(after.grid[5, 4]) == C.KIND_ID["wood"]
