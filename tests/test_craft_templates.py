"""give_<item> templates (teleport postconditions, impossible teleports) and hierarchies."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from smjax.envs.craft import constants as C
from smjax.envs.craft import default_hierarchy_name, from_ascii, inventory_dict
from smjax.options import Hierarchy, teleport_step

ENV, PARAMS = smjax.make("craft/get_gem", observation="none")
TEMPLATES = ENV.templates()


COUNTED = {"give_iron_x2": "iron", "give_stick_x2": "stick", "give_wood_x2": "wood"}


def test_one_template_per_item_with_caps_and_durations():
    assert set(TEMPLATES) == {f"give_{i}" for i in C.ITEMS} | set(COUNTED) and len(TEMPLATES) == 27
    for name, item in COUNTED.items():  # two units: twice the cap and the nominal duration
        assert TEMPLATES[name].k_max == 2 * C.STEP_CAP[item]
        assert TEMPLATES[name].nominal_steps == 2 * C.NOMINAL_STEPS[item]
    for item in C.ITEMS:
        tpl = TEMPLATES[f"give_{item}"]
        assert tpl.k_max == C.STEP_CAP[item] and tpl.teleport is not None
    nominal = {"wood": 25, "iron": 25, "stick": 40, "axe": 50, "bridge": 50, "gold": 100,
               "gem": 100}
    for item, d in nominal.items():
        assert TEMPLATES[f"give_{item}"].nominal_steps == d
    assert TEMPLATES["give_axe"].k_max == 400 and TEMPLATES["give_wood"].k_max == 100


def _run_teleports(name: str, world_task: str, count: int = 64, holding: dict | None = None):
    env, params = smjax.make(f"craft/{world_task}", observation="none")
    tpl = env.templates()[name]
    keys = jax.random.split(jax.random.PRNGKey(11), count)
    _, states = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    if holding:
        inv = np.zeros(C.NUM_KINDS, np.int32)
        for item, n in holding.items():
            inv[C.KIND_ID[item]] = n
        states = states.replace(inventory=jnp.broadcast_to(jnp.asarray(inv), (count, C.NUM_KINDS)))
    jumped, actions = jax.vmap(tpl.teleport, in_axes=(0, 0, None))(keys, states, params)
    after = jax.vmap(lambda k, s: teleport_step(env, tpl, k, s, params)[1])(keys, states)
    return env, params, tpl, states, jumped, actions, after


@pytest.mark.parametrize("item", ["iron", "grass", "wood", "rock"])
def test_primitive_teleport_stands_next_to_the_item_and_picks_it_up(item):
    _, params, tpl, states, jumped, actions, after = _run_teleports(f"give_{item}", "make_axe")
    kind = C.KIND_ID[item]
    assert np.all(np.asarray(actions) == C.USE)
    for i in range(states.grid.shape[0]):
        grid = np.asarray(states.grid[i])
        x, y = np.asarray(jumped.pos[i])
        dx, dy = C.DIRECTION_DELTAS[int(jumped.direction[i])]
        assert grid[x, y] == C.EMPTY and grid[x + dx, y + dy] == kind
        assert int(after.inventory[i, kind]) == 1
        assert np.sum(np.asarray(after.grid[i]) == kind) == 3  # one of the four picked
        assert bool(tpl.satisfied(jax.tree.map(lambda a: a[i], after), params))


@pytest.mark.parametrize("item", ["plank", "stick", "bridge", "axe", "bow", "goldarrow"])
def test_crafted_teleport_adds_the_item_at_its_workshop(item):
    task = "make_goldarrow" if item == "goldarrow" else "make_axe"
    _, params, tpl, states, jumped, actions, after = _run_teleports(f"give_{item}", task, 16)
    workshop = C.WORKSHOP_OF[item]
    for i in range(16):
        grid = np.asarray(states.grid[i])
        x, y = np.asarray(jumped.pos[i])
        dx, dy = C.DIRECTION_DELTAS[int(jumped.direction[i])]
        assert grid[x, y] == C.EMPTY and grid[x + dx, y + dy] == workshop
        # From an empty inventory: the item is held after the tick (the USE fires nothing).
        assert inventory_dict(jax.tree.map(lambda a: a[i], after)) == {item: 1}
        assert bool(tpl.satisfied(jax.tree.map(lambda a: a[i], after), params))
        assert not bool(tpl.initiation(jax.tree.map(lambda a: a[i], after), params))


def test_crafted_teleport_then_use_follows_the_multi_fire_rules():
    # The reference adds the stick and then USEs the toolshed: with iron held, shears fire
    # and consume the stick (give_stick is not satisfied afterwards). We keep that quirk.
    *_, after = _run_teleports("give_stick", "make_axe", 4, holding={"iron": 1})
    for i in range(4):
        assert inventory_dict(jax.tree.map(lambda a: a[i], after)) == {"shears": 1}


def test_impossible_teleport_is_a_noop_step():
    # A map without wood: give_wood has nowhere to stand.
    env, params = smjax.make("craft/get_gold", observation="none")
    state, params = from_ascii(smjax.envs.craft.REFERENCE_GOLD_MAP.replace("w", "."), "get_gold")
    tpl = env.templates()["give_wood"]
    jumped, action = tpl.teleport(jax.random.PRNGKey(0), state, params)
    assert int(action) == C.NOOP
    for a, b in zip(jax.tree.leaves(jumped), jax.tree.leaves(state)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    _, after, reward, term, trunc, _ = teleport_step(env, tpl, jax.random.PRNGKey(0), state, params)
    np.testing.assert_array_equal(np.asarray(after.grid), np.asarray(state.grid))
    assert tuple(np.asarray(after.pos)) == (8, 4) and int(after.step) == 1
    assert inventory_dict(after) == {} and float(reward) == 0.0 and not bool(term)
    # A map without a workshop 2: give_bridge is impossible too and adds nothing.
    no_factory = smjax.envs.craft.REFERENCE_GOLD_MAP.replace("2", ".")
    state2, params2 = from_ascii(no_factory, "get_gold")
    jumped, action = env.templates()["give_bridge"].teleport(jax.random.PRNGKey(0), state2, params2)
    assert int(action) == C.NOOP and inventory_dict(jumped) == {}
    # give_wood_x2 on it adds nothing either (no unit is promised without the USE's)
    jumped, action = env.templates()["give_wood_x2"].teleport(jax.random.PRNGKey(0), state, params)
    assert int(action) == C.NOOP and inventory_dict(jumped) == {}


@pytest.mark.parametrize("world_task", ["get_gold", "make_goldarrow", "get_gem"])
def test_treasure_teleport_crosses_its_barrier(world_task):
    # Gold (gem) behind water (stone): give_X stands in a barrier cell next to it (clearing
    # that cell, as the learned option's bridge or axe would) or in an open one, then grabs it.
    treasure = "gem" if world_task == "get_gem" else "gold"
    barrier = C.STONE if treasure == "gem" else C.WATER
    _, params, tpl, states, jumped, actions, after = _run_teleports(f"give_{treasure}", world_task)
    assert np.all(np.asarray(actions) == C.USE)
    for i in range(states.grid.shape[0]):
        grid, new = np.asarray(states.grid[i]), np.asarray(after.grid[i])
        x, y = np.asarray(after.pos[i])  # (the USE leaves the stand cell as it is)
        dx, dy = C.DIRECTION_DELTAS[int(after.direction[i])]
        assert grid[x + dx, y + dy] == C.KIND_ID[treasure] and grid[x, y] in (C.EMPTY, barrier)
        changed = set(zip(*np.nonzero(grid != new)))
        assert changed == {(x, y), (x + dx, y + dy)} - ({(x, y)} if grid[x, y] == C.EMPTY else set())
        assert new[x, y] == C.EMPTY and new[x + dx, y + dy] == C.EMPTY
        assert inventory_dict(jax.tree.map(lambda a: a[i], after)) == {treasure: 1}
    # From the reference gold map (no open neighbour) every stand cell is a water cell.
    state, params = from_ascii(smjax.envs.craft.REFERENCE_GOLD_MAP, "get_gold")
    picks = jax.vmap(TEMPLATES["give_gold"].teleport, in_axes=(0, None, None))(
        jax.random.split(jax.random.PRNGKey(3), 200), state, params)[0].pos
    assert {tuple(p) for p in np.asarray(picks).tolist()} == {(5, 1), (7, 1), (6, 2)}


@pytest.mark.parametrize("name,held", [("give_wood_x2", 0), ("give_wood_x2", 1),
                                       ("give_iron_x2", 0), ("give_iron_x2", 1),
                                       ("give_stick_x2", 0), ("give_stick_x2", 1)])
def test_counted_teleport_holds_the_promised_count(name, held):
    item = COUNTED[name]
    _, params, tpl, states, jumped, actions, after = _run_teleports(
        name, "make_flag", 16, holding={item: held} if held else None)
    for i in range(16):
        before_i, after_i = (jax.tree.map(lambda a: a[i], t) for t in (states, after))
        assert bool(tpl.initiation(before_i, params))
        assert inventory_dict(after_i) == {item: 2}
        assert bool(tpl.satisfied(after_i, params)) and not bool(tpl.initiation(after_i, params))
        # a primitive's second unit comes off the map (one cell fewer), a stick's from nothing
        cells = C.KIND_ID[item] if item != "stick" else C.WORKSHOPS[1]
        fewer = np.sum(np.asarray(before_i.grid) == cells) - np.sum(np.asarray(after_i.grid) == cells)
        assert fewer == (1 if item != "stick" else 0)


def test_recipe_children_promise_what_one_use_needs():
    # In every recipe hierarchy, holding what an option's give children promise and USEing
    # its workshop yields the option's item (multi-fire USE included).
    from smjax.envs.craft.recipe_plan import fire_recipes_np
    for task in C.TASKS:
        h = smjax.make(f"craft/{task}", observation="none")[0].hierarchies()["recipe"]
        for option, kids in h.children.items():
            item, count = (C.TASKS[option], 1) if option in C.TASKS else C.give_target(option)
            if item not in C.CRAFTED or count > 1:
                continue
            inv = np.zeros(C.NUM_KINDS, np.int64)
            for kid in kids:
                if kid.startswith("give_"):
                    what, n = C.give_target(kid)
                    inv[C.KIND_ID[what]] = n
            assert fire_recipes_np(inv, C.WORKSHOP_OF[item])[C.KIND_ID[item]] >= 1, (task, option, kids)
    flag = smjax.make("craft/make_flag")[0].hierarchies()["recipe"]
    prims = tuple(C.ACTION_NAMES)
    assert flag.children["make_flag"] == ("give_stick_x2", "give_cloth", "give_iron_x2") + prims
    assert flag.children["give_stick_x2"] == ("give_stick", "give_wood") + prims
    assert [C.give_target(n) for n in ("give_wood", "give_iron_x2")] == [("wood", 1), ("iron", 2)]
    for bad in ("give_cake", "take_wood", "give_wood_xx"):
        with pytest.raises(ValueError, match="not a craft give template"):
            C.give_target(bad)


def test_teleport_picks_uniformly_among_all_stand_cells():
    text = """\
############
#..........#
#..........#
#..........#
#..........#
#..........#
#....w.....#
#..........#
#..........#
#.........@#
#.w#.......#
############""".replace("#.w#", "#.wS")
    state, params = from_ascii(text, "get_wood")
    tpl = TEMPLATES["give_wood"]
    keys = jax.random.split(jax.random.PRNGKey(5), 600)
    jumped, _ = jax.vmap(tpl.teleport, in_axes=(0, None, None))(keys, state, params)
    picks = {(int(x), int(y), int(d)) for (x, y), d in zip(np.asarray(jumped.pos),
                                                           np.asarray(jumped.direction))}
    # wood at (5, 5): 4 stand cells; wood at (2, 1): (1, 1) and (2, 2) ((3, 1) is stone).
    expect = {(5, 6, C.DOWN), (5, 4, C.UP), (6, 5, C.LEFT), (4, 5, C.RIGHT),
              (1, 1, C.RIGHT), (2, 2, C.DOWN)}
    assert picks == expect


def test_hierarchies_per_task():
    for task in C.TASKS:
        env, _ = smjax.make(f"craft/{task}", observation="none")
        hs = env.hierarchies()
        assert list(hs)[0] == default_hierarchy_name(task)
        assert {"flat", "recipe"} <= set(hs)
        assert all(isinstance(h, Hierarchy) and h.task == task for h in hs.values())
        assert hs["flat"].children == {task: C.ACTION_NAMES}
        assert hs["flat"].option_names == (task,)
    gem = smjax.make("craft/get_gem")[0].hierarchies()["paper"]
    prims = list(C.ACTION_NAMES)
    assert dict(gem.children) == {
        "get_gem": tuple(["give_axe"] + prims),
        "give_axe": tuple(["give_stick", "give_iron"] + prims),
        "give_stick": tuple(["give_wood"] + prims),
        "give_iron": tuple(prims),
        "give_wood": tuple(prims),
    }
    assert gem.level("give_wood") == 4 and gem.option_names[0] == "get_gem"
    gold = smjax.make("craft/get_gold")[0].hierarchies()["paper"]
    assert dict(gold.children) == {
        "get_gold": tuple(["give_bridge"] + prims),
        "give_bridge": tuple(["give_wood", "give_iron"] + prims),
        "give_wood": tuple(prims),
        "give_iron": tuple(prims),
    }
    assert default_hierarchy_name("get_gem") == "paper"
    assert default_hierarchy_name("make_bow") == "recipe"
    bow = smjax.make("craft/make_bow")[0].hierarchies()["recipe"]
    assert bow.children["make_bow"][:2] == ("give_rope", "give_bundle")
    assert bow.children["give_bundle"][:2] == ("give_wood_x2", "give_grass")
    assert bow.children["give_grass"] == tuple(prims)
    with pytest.raises(ValueError, match="unknown craft task"):
        default_hierarchy_name("make_cake")
