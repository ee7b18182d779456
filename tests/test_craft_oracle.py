"""The scripted Craft oracle: solves tasks on fresh maps, returns valid actions, never crashes."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import smjax
from smjax.envs.craft import constants as C
from smjax.envs.craft import dynamics, from_ascii, make_params, oracle as O

TASKS = ("get_wood", "make_stick", "get_gem", "get_gold")
SEEDS = 6


def _run(state, params):
    """Play the oracle (goal read from params: one compile for every task) to the end."""
    def cond(c):
        return ~c[1]

    def body(c):
        s, _, stuck = c
        action, info = O.oracle_decide_traced(s, params.goal)
        s = dynamics.transition(s, action)
        _, term, trunc = dynamics.reward_and_done(s, params)
        return s, term | trunc, stuck | info["stuck"]

    s, _, stuck = jax.lax.while_loop(cond, body, (state, jnp.bool_(False), jnp.bool_(False)))
    reward, _, _ = dynamics.reward_and_done(s, params)
    return s, reward, stuck


_run_batch = jax.jit(jax.vmap(_run, in_axes=(0, None)))


def _fresh(task, n, seed=0):
    env, params = smjax.make(f"craft/{task}", observation="none")
    keys = jax.random.split(jax.random.key(seed), n)
    states = jax.vmap(lambda k: env.initial_state(k, params))(keys)
    return env, params, states


@pytest.fixture(scope="module")
def outcomes():
    out = {}
    for task in TASKS:
        _, params, states = _fresh(task, SEEDS)
        final, reward, stuck = _run_batch(states, params)
        out[task] = (params, final, np.asarray(reward), np.asarray(stuck))
    return out


@pytest.mark.parametrize("task", TASKS)
def test_oracle_solves_fixed_seeds_within_cap(outcomes, task):
    params, final, reward, stuck = outcomes[task]
    held = np.asarray(final.inventory[:, int(params.goal)])
    steps = np.asarray(final.step)
    assert (held > 0).all(), (task, steps)
    assert (steps <= int(params.max_steps)).all() and not stuck.any()
    best = 0.9 if task == "get_gem" else 1.0  # the axe is kept: get_gem's return is <= 0.9
    assert (reward <= best + 1e-6).all() and reward.mean() >= best - 0.1


def test_plan_covers_every_item_and_knows_the_recipe_quirks():
    plans = O.solvable_items()
    assert all(p is not None for p in plans.values()), plans
    k = C.KIND_ID
    # iron before the stick would turn the stick into shears at the toolshed
    assert O.ORDERS[k["axe"]] == (k["stick"], k["iron"])
    # plank fires before hammer at the workbench: a hammer needs two wood
    assert O.COUNTS[k["hammer"]][k["wood"]] == 2
    assert plans["gem"][1] == 1 and plans["gold"][1] == 0  # axe kept, bridge used up


def test_static_and_traced_goal_agree():
    env, params, states = _fresh("get_gem", SEEDS, seed=3)
    a = jax.jit(jax.vmap(lambda s: O.oracle_action(s, params, "get_gem")))(states)
    b = jax.vmap(_act, in_axes=(0, None))(states, params)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), task=st.sampled_from(TASKS + ("make_bench",)),
       steps=st.integers(0, 40))
def test_every_action_is_a_primitive(seed, task, steps):
    """From fresh maps and from states the oracle itself or random play reaches."""
    if task not in _NEW:
        _NEW[task] = _jit_new_state(task)
    params, new_state = _NEW[task]
    state = new_state(jax.random.key(seed))
    rng = np.random.default_rng(seed)
    for _ in range(steps % 8):
        state = _step(state, jnp.int32(rng.integers(0, 5)))
    for _ in range(3):
        a = int(_act(state, params))
        assert 0 <= a < C.NUM_ACTIONS
        state = _step(state, jnp.int32(a))


_NEW: dict = {}


def _jit_new_state(task):
    env, params = smjax.make(f"craft/{task}", observation="none")
    return params, jax.jit(lambda k: env.initial_state(k, params))


_act = jax.jit(lambda s, p: O.oracle_action(s, p))
_decide = jax.jit(lambda s, p: O.oracle_decide_traced(s, p.goal))
_step = jax.jit(dynamics.transition)


def _tile(state):
    """One state as a batch of SEEDS copies (keeps ``_run_batch`` at one compiled shape)."""
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (SEEDS,) + x.shape), state)

WALLED = """\
############
#..........#
#.....i....#
#..w...gg..#
#....0.....#
#....2.....#
#...1......#
#..........#
#..........#
#0.........#
#@1........#
############"""

NO_WOOD = """\
############
#..........#
#....i.....#
#...g..r...#
#......1...#
#....@.....#
#..........#
#..2.......#
#.....0....#
#..........#
#..........#
############"""


@pytest.mark.parametrize("text,task", [(WALLED, "make_stick"), (NO_WOOD, "get_wood"),
                                       (NO_WOOD, "get_gold")])
def test_unreachable_goal_gives_an_action_and_says_stuck(text, task):
    """Agent boxed in by workshops; a map without wood; gold on a map without any."""
    if text is NO_WOOD:  # from_ascii refuses a get_X map without X: the task goes in after
        state, _ = from_ascii(text, task="get_iron", max_steps=30)
        params = make_params(task, max_steps=30, fixed_state=state)
    else:
        state, params = from_ascii(text, task=task, max_steps=30)
    action, info = _decide(state, params)
    assert 0 <= int(action) < C.NUM_ACTIONS and bool(info["stuck"])
    final, reward, stuck = _run_batch(_tile(state), params)
    assert bool(stuck[0]) and float(reward[0]) == 0.0 and int(final.step[0]) == 30


def test_grabs_an_obstacle_only_when_walled_off():
    """Wood behind a wall of rock: the oracle grabs one rock, walks through, gets the wood."""
    text = """\
############
#.....r.w..#
#.....r....#
#.....r....#
#.....r....#
#..@..r....#
#.....r....#
#.....r....#
#.....r....#
#.....r....#
#.....r....#
############"""
    state, params = from_ascii(text, task="get_wood")
    final, reward, stuck = _run_batch(_tile(state), params)
    assert int(final.inventory[0, C.KIND_ID["wood"]]) == 1
    assert int(final.inventory[0, C.KIND_ID["rock"]]) == 1 and abs(float(reward[0]) - 0.9) < 1e-6


# Fresh map (seed 0, episode 423 of craft_ceiling): the gold's two open approaches, (10, 3)
# and (8, 1), are workshops; reaching it takes a first bridge over the diagonal water cell.
TWO_BRIDGES = """\
############
#..i......g#
#w.i......g#
#.i..r.....#
#.........r#
#..g@..0...#
#..........#
#....w...w.#
#..g......2#
#w.rr....~~#
#i......1~G#
############"""


def test_gold_behind_workshops_takes_two_bridges():
    state, params = from_ascii(TWO_BRIDGES, task="get_gold")
    final, reward, stuck = _run_batch(_tile(state), params)
    assert int(final.inventory[0, C.GOLD]) == 1 and not bool(stuck[0])
    assert int(final.step[0]) <= int(params.max_steps)


def test_oracle_hierarchy_builds_with_controllers():
    env, params = smjax.make("craft/get_gem", observation="none")
    h = O.oracle_hierarchy(env)
    tpl = h.templates["give_axe"]
    assert tpl.teleport is None and tpl.controller is not None
    state = env.initial_state(jax.random.key(1), params)
    a = jax.jit(tpl.controller)(jax.random.key(0), state, None)
    assert int(a) == int(_decide(state, params.replace(goal=jnp.int32(C.AXE)))[0])
