"""A hierarchy passed to ``run`` as an argument (issue 17): declared inline, no subclass."""
import dataclasses

import numpy as np
import pytest

import smjax
from hier_env import make_keydoor
from smjax.options import declare
from smjax.train import TrainConfig
from smjax.train.config import ConfigError
from smjax.train.policy import load_trained
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
    with pytest.raises(ValueError, match="declared in code"):
        load_trained(out)
    with pytest.raises(ValueError, match="not trained with this hierarchy"):
        load_trained(out, hierarchy=other)

@pytest.mark.slow
def test_a_craft_hierarchy_declared_inline_trains_and_plays_back(tmp_path):
    env, _ = smjax.make("craft/make_stick", **ENV)
    wood = dataclasses.replace(env.templates()["give_wood"], k_max=60)  # a template of our own
    h = _two_levels(env, wood)
    res = run("craft/make_stick", CFG, [0], tmp_path / "run", env_overrides=ENV,
              progress=False, hierarchy=h)
    engine, bank, learned, seeds = load_trained(tmp_path / "run", hierarchy=h)
    assert engine.h is h and seeds == [0]
    assert res["config"]["hierarchy_used"] == "declared:make_stick"
    assert [lv["template"] for lv in res["levels"]] == ["make_stick", "give_wood"]
    assert np.isfinite(res["final_success"]).all()


def test_bad_hierarchy_arguments_are_refused_before_training(tmp_path):
    env, _ = smjax.make("craft/make_stick", **ENV)
    with pytest.raises(ConfigError, match="flat method"):
        run("craft/make_stick", CFG.replace(method="flat"), [0], env_overrides=ENV,
            progress=False, hierarchy=_two_levels(env))
    with pytest.raises(ConfigError, match="a name or a smjax.options.Hierarchy"):
        run("craft/make_stick", CFG, [0], env_overrides=ENV, progress=False,
            hierarchy={"make_stick": ["give_wood"]})
    with pytest.raises(ConfigError, match="contradicts"):
        run("craft/make_stick", CFG.replace(hierarchy="recipe"), [0], env_overrides=ENV,
            progress=False, hierarchy="flat")
