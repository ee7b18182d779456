"""The environment contract (``smjax.testing``) on every environment family, and on
deliberately broken environments, for which the harness must name the broken property.

Compile time dominates on a CPU, so the default suite checks the small test
environments, one Craft task and the broken environments with small batches; the other
Craft worlds, Fetch and football are marked slow. The Craft check here replaces
test_craft_api's hand-written "vmapped batch equals unbatched runs" test.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.custom_batching import custom_vmap

import smjax
from envs_for_tests import Corridor
from hier_env import KeyDoor, make_keydoor
from smjax.core import spaces
from smjax.options import OptionTemplate, declare
from smjax.testing import assert_trees_close, check_env, check_hierarchy

SMALL = dict(num_envs=4, steps=16)  # shared by check_env and check_hierarchy: one rollout program


# ---- environments that meet the contract -------------------------------------------------
def test_corridor_meets_the_contract():
    env = Corridor()
    check_env(env, env.default_params, **SMALL)


def test_keydoor_and_its_templates_meet_the_contract():
    env, params = make_keydoor()
    check_env(env, params, **SMALL)
    check_hierarchy(env, params, "scripted", **SMALL)  # a teleport and a controller


def test_craft_plain_world_and_an_inline_hierarchy():
    # max_steps=3 ends episodes inside the rollout, so the auto-reset path is checked on
    # the task's own params (no max_steps cut by the harness).
    env, params = smjax.make("craft/get_wood", max_steps=3)
    check_env(env, params, **SMALL)
    # A primitive's teleport (USE picks it up) and a crafted item's (added by the jump).
    hierarchy = declare(env, "get_wood", {"get_wood": ["give_wood", "give_stick", "primitives"]})
    check_hierarchy(env, params, hierarchy, **SMALL)


def test_auto_reset_lives_in_the_base_class():
    """No environment family overrides ``step``; each declares the ``initial_state`` hook
    that lets the base class's auto-reset observe only the state it keeps."""
    from smjax.core.env import Environment
    from smjax.envs.craft import CraftEnv
    from smjax.envs.fetch import FetchEnv
    from smjax.envs.football import FootballEnv

    for cls in (CraftEnv, FetchEnv, FootballEnv):
        assert cls.step is Environment.step, f"{cls.__name__} overrides step"
        assert cls.initial_state is not Environment.initial_state, cls.__name__
        assert cls.reset_env is Environment.reset_env, f"{cls.__name__} overrides reset_env"
    assert FootballEnv.reset_ignores_key and not CraftEnv.reset_ignores_key


def test_the_generic_auto_reset_path_equals_the_hook_path():
    """An environment with ``initial_state`` steps exactly as if it had only ``reset_env``
    (the generic path: observe both, select the observation)."""
    class Generic(type(smjax.make("craft/get_wood")[0])):
        has_initial_state = False  # take the generic path of Environment.step

    env, params = smjax.make("craft/get_wood", max_steps=2)
    generic = Generic(env.config)
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    step_generic = jax.jit(jax.vmap(generic.step, in_axes=(0, 0, 0, None)))
    keys = jax.random.split(jax.random.PRNGKey(3), 8)
    _, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    for t in range(3):  # max_steps=2: every environment resets at t = 1
        keys = jax.vmap(lambda k: jax.random.fold_in(k, t))(keys)
        actions = jnp.arange(8) % 5
        out = step(keys, state, actions, params)
        assert_trees_close(out, step_generic(keys, state, actions, params),
                           prop="hook == generic", who="craft", exact=True)
        state = out[1]


def _notebook_env():
    """The environment notebooks/custom_env.ipynb defines (its cell run here, unchanged)."""
    path = Path(__file__).resolve().parent.parent / "notebooks" / "custom_env.ipynb"
    cells = [c for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]
    source = next("".join(c["source"]) for c in cells if "class KeyChest" in "".join(c["source"]))
    namespace = {"jax": jax, "jnp": jnp, "np": np}
    exec(compile(source, str(path), "exec"), namespace)
    return namespace["KeyChest"]()


def test_the_notebook_environment_meets_the_contract():
    env = _notebook_env()
    check_env(env, env.default_params.replace(max_steps=4), **SMALL)
    check_hierarchy(env, env.default_params, "paper", **SMALL)


def test_an_adapted_gymnax_environment_meets_the_contract():
    gymnax = pytest.importorskip("gymnax", reason="gymnax is an optional peer dependency")
    from smjax.core.adapters import from_gymnax

    env, params = from_gymnax(*gymnax.make("CartPole-v1"))
    # a short time limit: episodes end inside the rollout whatever the pole does
    check_env(env, params.replace(max_steps_in_episode=8), **SMALL)


@pytest.mark.slow
@pytest.mark.parametrize("task,hierarchy", [("get_gem", "paper"), ("get_gold", "paper"),
                                            ("make_bow", "recipe")])
def test_craft_worlds(task, hierarchy):
    # cave (gem behind stone), island (gold behind water), and a deep recipe in a plain world
    env, params = smjax.make(f"craft/{task}", observation="compact")
    check_env(env, params, **SMALL)
    check_hierarchy(env, params, hierarchy, **SMALL)


@pytest.mark.slow
def test_fetch_stack3():
    env, params = smjax.make("fetch/stack3", max_steps=4)
    # Rendering needs an OpenGL backend; test_fetch_render_brax.py checks it where one exists.
    # The tolerances are Fetch's own (contract_tolerances: MJX solver residuals).
    check_env(env, params, num_envs=2, steps=8, render=False)
    check_hierarchy(env, params, "paper", num_envs=2, steps=8, num_states=8, loop_states=2)


def test_an_environment_declares_its_tolerances():
    class Jittery(BatchSensitiveCorridor):  # rewards differ by 1 between vmap and loop
        contract_tolerances = (0.0, 1.5)

    env = Jittery()
    check_env(env, env.default_params, **SMALL)
    with pytest.raises(AssertionError, match="vmap == loop"):  # a given atol still wins
        check_env(env, env.default_params, atol=1e-6, **SMALL)
    assert smjax.make("fetch/stack1")[0].contract_tolerances[1] >= 1e-4


@pytest.mark.slow
def test_football():
    env, params = smjax.make("football/11v11_easy", observation="paper", game_length=6)
    check_env(env, params, num_envs=2, steps=8)
    check_hierarchy(env, params, "paper", num_envs=2, steps=8, num_states=8, loop_states=2)


# ---- deliberately broken environments: the harness names what is wrong ------------------
class LoudCorridor(Corridor):
    """Observations reach 2 in a Box(0, 1)."""

    def get_obs(self, state, params):
        return (2 * jax.nn.one_hot(state.position, self.length)).astype(jnp.uint8)


@custom_vmap
def _batch_sensitive(x):
    return x


@_batch_sensitive.def_vmap
def _batch_sensitive_rule(axis_size, in_batched, x):
    return x + 1.0, in_batched[0]  # a batched call computes something else


class BatchSensitiveCorridor(Corridor):
    """Rewards change under vmap."""

    def step_env(self, key, state, action, params):
        obs, state, reward, term, trunc, info = super().step_env(key, state, action, params)
        return obs, state, _batch_sensitive(reward), term, trunc, info


class NoResetCorridor(Corridor):
    """Overrides ``step`` and forgets to reset finished episodes."""

    def step(self, key, state, action, params=None):
        obs, state, reward, term, trunc, info = self.step_env(key, state, action, params)
        return obs, state, reward, term, trunc, dict(info, final_observation=obs)


class WrongDoorKeyDoor(KeyDoor):
    """give_key teleports onto the door's cell instead of the key's."""

    def templates(self):
        good = super().templates()["give_key"]

        def to_door(key, state, params):
            return state.replace(pos=state.door_pos), jnp.asarray(2)

        return {"give_key": OptionTemplate(name="give_key", satisfied=good.satisfied, k_max=12,
                                           initiation=good.initiation, teleport=to_door)}


class WrongOpenKeyDoor(KeyDoor):
    """open_door, initiable only with the key, teleports beside the door and does nothing."""

    def templates(self):
        def beside_door(key, state, params):
            return state.replace(pos=jnp.maximum(state.door_pos - 1, 0)), jnp.asarray(0)

        return super().templates() | {"open_door": OptionTemplate(
            name="open_door", satisfied=lambda s, p: s.opened, k_max=12,
            initiation=lambda s, p: s.has_key & ~s.opened, teleport=beside_door)}


class WildControllerKeyDoor(KeyDoor):
    """A controller that returns action 7 of Discrete(3)."""

    def templates(self):
        return {"walk": OptionTemplate(name="walk", satisfied=lambda s, p: s.opened, k_max=5,
                                       controller=lambda k, s, p: jnp.asarray(7))}


class NanRewardCorridor(Corridor):
    """Rewards NaN on every step."""

    def step_env(self, key, state, action, params):
        obs, state, reward, term, trunc, info = super().step_env(key, state, action, params)
        return obs, state, reward + jnp.nan, term, trunc, info


class GridPastTheEndCorridor(Corridor):
    """Declares an observation grid that runs past the observation's end."""

    def observation_layout(self, params=None):
        return ((0, 4, 4, 4),)


class BlankTextCorridor(Corridor):
    """Describes every state as an empty string (None is the way to say "no text form")."""

    def describe(self, state, params=None):
        return ""


@pytest.mark.parametrize("env,match", [
    (LoudCorridor(), "observation in space failed for tests/corridor"),
    (BlankTextCorridor(), "describe failed for tests/corridor: describe returned ''"),
    (GridPastTheEndCorridor(), "spaces failed for tests/corridor: observation_layout: "),
    (BatchSensitiveCorridor(), r"vmap == loop failed for tests/corridor: step 0, env 0: "
                               r"leaf \[2\]"),  # the reward
    (NoResetCorridor(), "auto-reset failed for tests/corridor"),
    (NanRewardCorridor(), "reward finite failed for tests/corridor: reward at step 0, env 0 is nan"),
], ids=["obs-outside-space", "blank-describe", "grid-past-the-end", "vmap-differs",
        "no-auto-reset", "nan-reward"])
def test_broken_env_is_named(env, match):
    with pytest.raises(AssertionError, match=match):
        check_env(env, env.default_params, **SMALL)


def test_describe_is_checked_where_rendering_is_skipped():
    # render=False is for environments without a graphics backend (Fetch); text needs none
    env = BlankTextCorridor()
    with pytest.raises(AssertionError, match="describe failed for tests/corridor"):
        check_env(env, env.default_params, render=False, **SMALL)


def test_broken_teleport_and_controller_are_named():
    env = WrongDoorKeyDoor()
    hierarchy = declare(env, "open_door", {"open_door": ["give_key", "primitives"]})
    with pytest.raises(AssertionError, match="teleport outcome failed for test/keydoor "
                                             "template 'give_key'"):
        check_hierarchy(env, env.default_params, hierarchy, **SMALL)
    env = WildControllerKeyDoor()
    hierarchy = declare(env, "open_door", {"open_door": ["walk", "primitives"]})
    with pytest.raises(AssertionError, match="controller action failed for test/keydoor "
                                             "template 'walk'"):
        check_hierarchy(env, env.default_params, hierarchy, **SMALL)


def test_a_teleport_behind_another_is_checked_on_its_outcomes():
    # random play seldom picks up the key: the broken open_door is reached through
    # give_key's teleport (8 states of 4 envs x 2 steps: none holds the key)
    env = WrongOpenKeyDoor()
    hierarchy = declare(env, "task", {"task": ["open_door", "primitives"],
                                      "open_door": ["give_key", "primitives"]})
    with pytest.raises(AssertionError, match="teleport outcome failed for test/keydoor "
                                             "template 'open_door': state"):
        check_hierarchy(env, env.default_params, hierarchy, num_envs=4, steps=2, num_states=8)


def test_a_teleport_initiable_nowhere_is_not_passed():
    env = WrongOpenKeyDoor()
    hierarchy = declare(env, "task", {"task": ["open_door", "primitives"]})  # no give_key
    with pytest.raises(AssertionError, match="teleport outcome failed for test/keydoor template "
                                             "'open_door': not checked: .* in 0 of 8 states"):
        check_hierarchy(env, env.default_params, hierarchy, num_envs=4, steps=2, num_states=8)


def test_comparisons_use_tolerances_for_floats_only():
    assert_trees_close({"x": jnp.float32(1.0)}, {"x": jnp.float32(1.0 + 1e-7)}, prop="p", who="w")
    with pytest.raises(AssertionError, match=r"p failed for w: here: leaf \['x'\]"):
        assert_trees_close({"x": jnp.float32(1.0)}, {"x": jnp.float32(1.001)}, prop="p", who="w",
                           where="here")
    with pytest.raises(AssertionError, match="values differ"):
        assert_trees_close(jnp.int32(1), jnp.int32(2), prop="p", who="w")
    with pytest.raises(AssertionError, match="values differ"):  # exact: same program twice
        assert_trees_close(jnp.float32(1.0), jnp.float32(1.0 + 1e-7), prop="p", who="w",
                           exact=True)


def test_spaces_contain():
    box, discrete = spaces.Box(0.0, 1.0, (2,)), spaces.Discrete(3, shape=(2,))
    assert bool(box.contains(jnp.array([0.0, 1.0])))
    assert not bool(box.contains(jnp.array([0.0, jnp.nan])))
    assert bool(discrete.contains(jnp.array([0, 2])))
    assert not bool(discrete.contains(jnp.array([0, 3])))
    assert not bool(discrete.contains(jnp.array([0.5, 1.0])))


@pytest.mark.slow  # each task's harness compiles its own programs: ~1-2 min on 2 cores
@pytest.mark.parametrize("task", ["craft/get_wood", "craft/make_stick", "craft/get_gem",
                                  "football/11v11_easy"])
def test_registered_environments_pass_the_harness_with_its_defaults(task):
    """What a user runs first: every argument left at its default (Fetch: in
    test_fetch_render_brax.py, which skips it without OpenGL)."""
    env, params = smjax.make(task)
    check_env(env, params)
    for name in env.hierarchies():
        check_hierarchy(env, params, name)
