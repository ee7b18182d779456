"""A task's best success below 1 (Hierarchy.success_ceiling): Craft declares it from its
recipes, and a root threshold at or above it is lowered to ``ceiling_fraction`` of it, so
the level can end (make_bench, best 0.8, ran its whole 40,000-episode root budget)."""
import jax.numpy as jnp
import pytest

import smjax
from hier_env import make_keydoor
from smjax.envs.craft import constants as C
from smjax.envs.craft.oracle import best_return, solvable_items
from smjax.options import HierarchyError, declare
from smjax.train import TrainConfig
from smjax.train.config import ConfigError
from smjax.train.plans import reachable_root_threshold
from smjax.train.run import run


def _craft_hierarchies(task):
    env, _ = smjax.make(f"craft/{task}", observation="none")
    return env.hierarchies()


@pytest.mark.parametrize("task", sorted(C.TASKS))
def test_every_craft_hierarchy_declares_its_tasks_best_return(task):
    uses_left = solvable_items()[C.TASKS[task]]
    assert uses_left is not None  # the recipe plan solves every task from nothing
    expected = round(1.0 - 0.1 * uses_left[1], 6)
    for name, h in _craft_hierarchies(task).items():
        assert h.success_ceiling == pytest.approx(expected), name  # flat keeps it too


def test_known_ceilings():
    # multi-fire USE leaves items over: get_gem keeps its axe, make_bench two items
    assert best_return("get_gem") == pytest.approx(0.9)
    assert best_return("make_bench") == pytest.approx(0.8)
    assert best_return("make_stick") == 1.0 and best_return("get_gold") == 1.0


def test_a_root_threshold_at_the_ceiling_is_lowered():
    h = _craft_hierarchies("make_bench")["recipe"]
    cfg = reachable_root_threshold(TrainConfig(), h)
    assert cfg.levels == {"make_bench": {"threshold": pytest.approx(0.72)}}
    assert cfg.for_level("make_bench").threshold == pytest.approx(0.72)
    assert cfg.for_level("give_hammer").threshold == 0.8  # template levels: F_o, best 1
    half = reachable_root_threshold(TrainConfig(ceiling_fraction=0.5), h)
    assert half.levels["make_bench"]["threshold"] == pytest.approx(0.4)


def test_a_reachable_threshold_is_left_alone():
    gem = _craft_hierarchies("get_gem")["paper"]
    cfg = TrainConfig()
    assert reachable_root_threshold(cfg, gem) is cfg  # 0.8 < 0.9: the paper's setting
    high = TrainConfig(threshold=0.95)
    gold = _craft_hierarchies("get_gold")["paper"]
    assert reachable_root_threshold(high, gold) is high  # best 1: any threshold <= 1 may pass
    lowered = reachable_root_threshold(high, gem)  # 0.95 on get_gem never passes
    assert lowered.levels["get_gem"]["threshold"] == pytest.approx(0.81)


def test_a_per_level_override_keeps_its_other_fields():
    h = _craft_hierarchies("make_bench")["recipe"]
    cfg = TrainConfig(levels={"make_bench": {"threshold": 0.85, "max_episodes_per_level": 900},
                              "give_hammer": {"threshold": 0.9}})
    out = reachable_root_threshold(cfg, h)
    assert out.levels["make_bench"] == {"threshold": pytest.approx(0.72),
                                        "max_episodes_per_level": 900}
    assert out.levels["give_hammer"] == {"threshold": 0.9}
    below = TrainConfig(levels={"make_bench": {"threshold": 0.7}})
    assert reachable_root_threshold(below, h) is below


@pytest.mark.parametrize("bad", [0, 1.5, -0.2, True, "0.9", None])
def test_bad_ceilings_and_fractions_are_refused(bad):
    env, _ = make_keydoor()
    with pytest.raises(HierarchyError, match="success_ceiling must be a number in"):
        declare(env, "open_door", {"open_door": ["primitives"]}, success_ceiling=bad)
    with pytest.raises(ConfigError, match="ceiling_fraction"):
        TrainConfig(ceiling_fraction=bad)


def test_a_run_ends_its_root_level_below_a_declared_ceiling_and_records_it(tmp_path):
    """KeyDoor scored at half (0.5 when the door opens, declared as the best): the root's
    0.8 could never be reached; it becomes 0.3 (a fraction of 0.6: the door opened in 60%
    of the episodes, as a short test can), the level ends, and the effective config
    (results, and the checkpoint's identity, so the run resumes as itself) carries it."""
    env, params = make_keydoor()
    h = declare(env, "open_door", {"open_door": ["give_key", "primitives"],
                                   "give_key": ["primitives"]},
                success=lambda s, p: 0.5 * s.opened.astype(jnp.float32), success_ceiling=0.5)
    cfg = TrainConfig(num_envs=16, rollout_ticks=16, updates_per_chunk=2, finetune="off",
                      ceiling_fraction=0.6, max_episodes_per_level=400, success_window=64, eval_envs=32,
                      checkpoint_every=0.0)
    out = tmp_path / "run"
    with pytest.warns(UserWarning, match=r"the root level ends at 0\.3 \(ceiling_fraction 0\.6"):
        res = run((env, params), cfg, [0], out, progress=False, hierarchy=h)
    assert res["config"]["levels"] == {"open_door": {"threshold": 0.3}}
    root = res["levels"][0]
    assert root["template"] == "open_door" and root["reached"] == [True]
    assert root["final_running_success"][0] >= 0.3
    assert max(res["final_success"]) <= 0.5
    again = run((env, params), cfg, [0], out, progress=False, hierarchy=h, resume=True)
    assert again["final_success"] == res["final_success"]
