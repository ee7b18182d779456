"""A hierarchy passed to ``run`` as an argument (issue 17): declared inline, no subclass."""
import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from hier_env import make_keydoor
from smjax.options import HierarchyError, declare
from smjax.train import TrainConfig
from smjax.train.config import ConfigError
from smjax.policy.hierarchies import declared_identity
from smjax.policy import PolicyError, load_policy
from smjax.train.run import run

CFG = TrainConfig(num_envs=16, rollout_ticks=8, updates_per_chunk=2, max_episodes_per_level=300,
                  success_window=32, gate_envs=16, eval_envs=16, finetune_max_episodes=100,
                  finetune_turn_episodes=50, checkpoint_every=0.0)
ENV = {"observation": "compact"}


def _two_levels(env, wood_template=None):
    """make_stick over give_wood; ``wood_template`` replaces Craft's own give_wood."""
    h = declare(env, "make_stick", {"make_stick": ["give_wood", "primitives"],
                                    "give_wood": ["primitives"]})
    if wood_template is None:
        return h
    return dataclasses.replace(h, templates={**h.templates, "give_wood": wood_template})


KEYDOOR_CFG = TrainConfig(num_envs=16, rollout_ticks=16, updates_per_chunk=2,
                          max_episodes_per_level=400, success_window=64, eval_envs=32,
                          finetune_max_episodes=200, finetune_turn_episodes=100,
                          checkpoint_every=0.0)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """The key-door test environment under a hierarchy declared here, with a template
    written here (give_key with a shorter tick budget): no subclass."""
    env, params = make_keydoor()
    key = dataclasses.replace(env.templates()["give_key"], k_max=10)
    h = declare(env, "open_door", {"open_door": ["give_key", "primitives"],
                                   "give_key": ["primitives"]})
    h = dataclasses.replace(h, templates={**h.templates, "give_key": key})
    out = tmp_path_factory.mktemp("declared") / "run"
    res = run((env, params), KEYDOOR_CFG, [0], out, progress=False, hierarchy=h)
    return env, params, h, out, res


def test_the_flat_method_trains_a_declared_hierarchys_flattening():
    env, params = make_keydoor()
    h = declare(env, "open_door", {"open_door": ["give_key", "reach_door", "use"],
                                   "give_key": ["primitives"]})
    cfg = KEYDOOR_CFG.replace(method="flat", max_episodes_per_level=100)
    res = run((env, params), cfg, [0], progress=False, hierarchy=h)
    assert res["config"]["hierarchy_used"] == "declared:open_door:flattened"
    assert [lv["template"] for lv in res["levels"]] == ["open_door"]


def test_a_declared_hierarchy_trains_and_is_named_in_the_results(trained):
    env, params, h, out, res = trained
    assert res["config"]["hierarchy_used"] == "declared:open_door"
    assert [lv["template"] for lv in res["levels"]] == ["open_door", "give_key"]
    assert all(0.0 <= s <= 1.0 for s in res["final_success"])


def test_resume_and_playback_need_the_same_declared_hierarchy(trained):
    env, params, h, out, res = trained
    other = env.hierarchies()["scripted"]
    with pytest.raises(ConfigError, match="hierarchy_declared"):
        run((env, params), KEYDOOR_CFG, [0], out, progress=False, resume=True, hierarchy=other)
    with pytest.raises(PolicyError, match="passed as \\(env, params\\)"):
        load_policy(out)
    with pytest.raises(PolicyError, match="declared in code"):
        load_policy(out, env=(env, params))
    with pytest.raises(PolicyError, match="not trained with this hierarchy"):
        load_policy(out, env=(env, params), hierarchy=other)
    policy = load_policy(out, env=(env, params), hierarchy=h)
    assert policy.hierarchy is h
    assert policy.evaluate()["success"] == res["final_success"]  # the run's own evaluation


@pytest.mark.slow
def test_a_craft_hierarchy_declared_inline_trains_and_plays_back(tmp_path):
    env, _ = smjax.make("craft/make_stick", **ENV)
    wood = dataclasses.replace(env.templates()["give_wood"], k_max=60)  # a template of our own
    h = _two_levels(env, wood)
    res = run("craft/make_stick", CFG, [0], tmp_path / "run", env_overrides=ENV,
              progress=False, hierarchy=h)
    policy = load_policy(tmp_path / "run", hierarchy=h)
    assert policy.hierarchy is h and policy.seeds == [0]
    assert res["config"]["hierarchy_used"] == "declared:make_stick"
    assert [lv["template"] for lv in res["levels"]] == ["make_stick", "give_wood"]
    assert np.isfinite(res["final_success"]).all()


def test_bad_hierarchy_arguments_are_refused_before_training(tmp_path):
    env, _ = smjax.make("craft/make_stick", **ENV)
    with pytest.raises(ConfigError, match="a name or a smjax.options.Hierarchy"):
        run("craft/make_stick", CFG, [0], env_overrides=ENV, progress=False,
            hierarchy={"make_stick": ["give_wood"]})
    with pytest.raises(ConfigError, match="contradicts"):
        run("craft/make_stick", CFG.replace(hierarchy="recipe"), [0], env_overrides=ENV,
            progress=False, hierarchy="flat")


# ---- a declared task success (success=) ---------------------------------------------------

SUCCESS_CFG = KEYDOOR_CFG.replace(finetune="off", max_episodes_per_level=200, success_window=32)


def _keydoor_h(env, **kw):
    return declare(env, "open_door", {"open_door": ["give_key", "primitives"],
                                      "give_key": ["primitives"]}, **kw)


def _numbers(res):
    """What a run computed (not how long it took)."""
    levels = [{k: lv[k] for k in ("template", "episodes", "env_steps", "reached",
                                  "final_running_success", "gate_success", "gate_attempts",
                                  "gate_env_steps")} for lv in res["levels"]]
    return levels, res["final_success"], res["episodes_to_threshold"]


@pytest.mark.slow  # ~60 s: two trainings; the tests below check what success= changes
def test_a_success_equal_to_the_default_gives_identical_numbers():
    """KeyDoor reports no info["success"], so the root's success is the episode return: 1
    exactly where the door ends the episode open. Declaring that as success= changes nothing."""
    env, params = make_keydoor()
    env.success_in_unit_interval = True  # both runs' gates may stop early alike
    base = run((env, params), SUCCESS_CFG, [0, 1], progress=False, hierarchy=_keydoor_h(env))
    same = run((env, params), SUCCESS_CFG, [0, 1], progress=False,
               hierarchy=_keydoor_h(env, success=lambda s, p: s.opened))
    assert _numbers(same) == _numbers(base)
    assert max(base["final_success"]) > 0  # it is a real comparison: the task was solved


def test_a_declared_success_replaces_the_environments_for_the_root():
    """A success that is never met keeps the root's level from ever reaching its threshold
    (the environment's reward still trains it), and final_success is 0."""
    env, params = make_keydoor()
    never = _keydoor_h(env, success=lambda s, p: jnp.zeros((), jnp.float32))
    res = run((env, params), SUCCESS_CFG, [0], progress=False, hierarchy=never)
    root = res["levels"][0]
    assert root["template"] == "open_door" and root["reached"] == [False]
    assert root["episodes"][0] >= SUCCESS_CFG.max_episodes_per_level
    assert res["final_success"] == [0.0]


def test_a_bad_success_is_refused_with_a_clear_error():
    env, params = make_keydoor()
    with pytest.raises(HierarchyError, match="success must be a function"):
        _keydoor_h(env, success=1.0)
    vector = _keydoor_h(env, success=lambda s, p: jnp.stack([s.opened, s.has_key]))
    with pytest.raises(HierarchyError, match=r"one scalar .* got shape \(2,\)"):
        run((env, params), SUCCESS_CFG, [0], progress=False, hierarchy=vector)
    broken = _keydoor_h(env, success=lambda s, p: s.no_such_field)
    with pytest.raises(HierarchyError, match="fails on the environment's state.*no_such_field"):
        run((env, params), SUCCESS_CFG, [0], progress=False, hierarchy=broken)
    text = _keydoor_h(env, success=lambda s, p: {"a": s.opened, "b": s.opened})
    with pytest.raises(HierarchyError, match="one scalar"):
        run((env, params), SUCCESS_CFG, [0], progress=False, hierarchy=text)


def test_declare_takes_templates_of_ones_own_and_success_is_in_the_identity():
    env, _ = make_keydoor()
    key = dataclasses.replace(env.templates()["give_key"], k_max=10)
    h = _keydoor_h(env, templates=[key])
    assert h.templates["give_key"] is key and h.templates["reach_door"] is not None
    assert _keydoor_h(env, templates={"give_key": key}).templates["give_key"] is key
    with pytest.raises(HierarchyError, match="registered as 'other'"):
        _keydoor_h(env, templates={"other": key})
    with pytest.raises(HierarchyError, match="OptionTemplates"):
        _keydoor_h(env, templates=["give_key"])
    assert "success" not in declared_identity(h)  # unchanged where none is declared

    def door_open(s, p):
        return s.opened

    assert declared_identity(_keydoor_h(env, success=door_open))["success"].endswith("door_open")
