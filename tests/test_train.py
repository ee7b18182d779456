"""Short end-to-end training runs on the key-and-door environment (real learning, CPU)."""
import json

import numpy as np
import pytest

from hier_env import make_keydoor
from smjax.train import ConfigError, TrainConfig
from smjax.train.run import run
from smjax.train.results import CURVE_COLUMNS
from smjax.viz.plots import PlotHook

SMALL = dict(num_envs=32, rollout_ticks=16, updates_per_chunk=4, max_episodes_per_level=4000,
             success_window=64, eval_envs=64, finetune_max_episodes=400,
             finetune_turn_episodes=200)


@pytest.fixture(scope="module")
def top_down_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("td")
    # with TensorBoard files (host-side logging; the compiled program is the same)
    res = run(make_keydoor(), TrainConfig(**SMALL, tensorboard=True), [0, 1], out, progress=False,
              hooks=[PlotHook()])
    return res, out


def test_two_level_top_down_learns_and_works_without_teleports(top_down_run):
    res, _ = top_down_run
    assert [lvl["template"] for lvl in res["levels"]] == ["open_door", "give_key"]
    assert all(all(lvl["reached"]) for lvl in res["levels"])
    # the final product executes its own learned give_key option: no teleports
    assert min(res["final_success"]) > 0.3
    assert all(e is not None and e > 0 for e in res["episodes_to_threshold"])
    # every level ended through the gate: the frozen policy itself reached the threshold
    for lvl in res["levels"]:
        assert all(a >= 1 for a in lvl["gate_attempts"]) and min(lvl["gate_success"]) >= 0.8
        assert all(n >= SMALL["eval_envs"] for n in lvl["gate_env_steps"])
        assert all(0.0 <= u < 1.0 for u in lvl["gate_uncalled"])
    assert res["levels"][0]["gate_uncalled"] == [0.0, 0.0]  # the root is always running


def test_a_level_does_not_end_on_exploration_luck():
    # A DQN that never trains and explores uniformly (epsilon 1): with the scripted key-door
    # templates its behaviour policy succeeds in every episode, so the running success
    # passes the threshold at once. Its greedy policy is an untrained network's argmax.
    agent = {"epsilon_start": 1.0, "epsilon_end": 1.0, "learning_starts": 10**9}
    # (only the root is examined: give_key's level gets a budget of one chunk, and there
    # is no fine-tuning after it)
    cfg = TrainConfig(algo="dqn", hierarchy="scripted", num_envs=32, rollout_ticks=16,
                      updates_per_chunk=2, success_window=64, max_episodes_per_level=160,
                      threshold=0.5, gate_envs=64, gate_interval=1, eval_envs=64, agent=agent,
                      levels={"give_key": {"max_steps_per_level": 1}}, finetune="off")
    root = run(make_keydoor(), cfg, [0, 1, 2], progress=False)["levels"][0]
    assert min(root["final_running_success"]) >= 0.5  # every seed's exploration "passed"
    for s in range(3):
        # the level ends exactly when the frozen policy passes its gate
        assert root["reached"][s] == (root["gate_success"][s] >= 0.5)
        if not root["reached"][s]:  # trained on to its budget, the gate retried on the way
            assert root["episodes"][s] >= 160 and root["gate_attempts"][s] >= 2
    assert not all(root["reached"])  # some untrained greedy policies fail (seeds 0 and 2)
    ungated = run(make_keydoor(), cfg.replace(gate=False), [0], progress=False)["levels"][0]
    assert ungated["reached"] == [True] and ungated["gate_attempts"] == [0]
    assert ungated["gate_uncalled"] == [None]


def test_results_contract(top_down_run):
    res, out = top_down_run
    on_disk = json.loads((out / "results.json").read_text())
    for key in ("env", "task", "method", "algo", "seeds", "threshold", "episodes_to_threshold",
                "env_steps_to_threshold", "final_success", "levels", "wall_seconds",
                "compile_seconds", "device", "jax_version", "smjax_version", "config"):
        assert key in on_disk, key
    assert on_disk["method"] == "top-down" and on_disk["seeds"] == [0, 1]
    assert len(on_disk["episodes_to_threshold"]) == 2 and len(on_disk["final_success"]) == 2
    for lvl in on_disk["levels"]:
        assert set(lvl) >= {"template", "level", "episodes", "env_steps"}
        assert len(lvl["episodes"]) == 2
    header = (out / "curves.csv").read_text().splitlines()[0]
    assert tuple(header.split(",")) == CURVE_COLUMNS
    assert (out / "curves.png").stat().st_size > 5000
    events = list((out / "tensorboard").glob("events.out.tfevents.*"))  # written on request
    assert events and events[0].stat().st_size > 100
    # the learner's own metrics, per seed and level, and per option while fine-tuning
    written = b"".join(e.read_bytes() for e in events)
    for tag in (b"seed_0/level_1_open_door/learner/entropy", b"seed_1/level_2_give_key/learner/approx_kl",
                b"/learner/kl_stopped", b"seed_0/level_1_open_door/running_success",
                b"seed_1/level_2_give_key/gate_uncalled"):
        assert tag in written, tag
    assert res["finetune"] is not None  # top-down fine-tunes by default
    # (joint, the default: every learned option under finetune/joint/NAME)
    for name in (b"open_door", b"give_key"):
        assert b"seed_0/finetune/joint/" + name + b"/learner/value_loss" in written
    # episodes to threshold are the per-level episodes summed, as the paper counts
    for s in range(2):
        assert on_disk["episodes_to_threshold"][s] == sum(l["episodes"][s] for l in on_disk["levels"])


def test_same_seed_same_numbers():
    # short levels and turns: what is compared is every number, not how well it learned
    cfg = TrainConfig(**(SMALL | {"max_episodes_per_level": 120, "finetune_max_episodes": 64,
                                  "finetune_turn_episodes": 32}))
    a = run(make_keydoor(), cfg, [3], progress=False)
    b = run(make_keydoor(), cfg, [3], progress=False)
    assert a["finetune"]["episodes"][0] > 0
    assert a["levels"] == b["levels"] and a["finetune"] == b["finetune"]
    assert a["final_success"] == b["final_success"]


@pytest.mark.parametrize("method", ["bottom-up", "flat"])
def test_baselines_run_through_the_same_engine(method):
    cfg = TrainConfig(**(SMALL | {"method": method, "max_episodes_per_level": 400}))
    res = run(make_keydoor(), cfg, [0], progress=False)
    names = [lvl["template"] for lvl in res["levels"]]
    assert names == {"bottom-up": ["give_key", "open_door"], "flat": ["open_door"]}[method]
    assert np.isfinite(res["final_success"]).all()


@pytest.mark.parametrize("field, value, message", [
    ("num_envs", 0, r"'num_envs' = 0: must be an integer in \[1, "),
    ("threshold", 1.5, r"'threshold' = 1.5: must be a number in \(0, 1\]"),
    ("threshold", 0, "threshold"),
    ("method", "sideways", "one of"),
    ("algo", "sarsa", "one of"),
    ("gamma", -0.1, "gamma"),
    ("gate", "yes", "'gate' = 'yes': must be true or false"),
    ("gate_envs", 0, "gate_envs"),
    ("gate_interval", 0, "gate_interval"),
])
def test_invalid_config_rejected_before_compile(field, value, message):
    with pytest.raises(ConfigError, match=message):
        TrainConfig(**{field: value})


def test_unknown_config_field_and_bad_seeds():
    with pytest.raises(ConfigError, match="unknown config field"):
        TrainConfig.from_dict({"num_env": 4})
    with pytest.raises(ValueError, match="distinct"):
        run(make_keydoor(), TrainConfig(**SMALL), [1, 1], progress=False)
    with pytest.raises(ValueError, match="unknown hierarchy"):
        run(make_keydoor(), TrainConfig(**(SMALL | {"hierarchy": "nope"})), [0], progress=False)


@pytest.mark.slow  # ~1-3 min of a 2-core CI; the key-door runs above check learning by default
@pytest.mark.parametrize("torso", ["mlp", "conv"])
def test_craft_get_wood_reaches_threshold_on_cpu(torso):
    # No acceptance gate (its own compile and 256 episodes): what this test examines is that
    # PPO learns Craft on the CPU, and final_success below runs the learned policy alone.
    # The gate is examined on the key-door runs above. "conv": the 3 x 3 window read by
    # convolutions (tests/test_conv_torso.py).
    cfg = TrainConfig(num_envs=64, rollout_ticks=32, updates_per_chunk=4, max_episodes_per_level=6000,
                      eval_envs=128, gate=False, finetune="off", agent={"torso": torso})
    res = run("craft/get_wood", cfg, [0], progress=False, env_overrides={"observation": "compact"})
    level = res["levels"][0]
    assert level["reached"] == [True] and level["final_running_success"][0] >= 0.8
    assert res["final_success"][0] > 0.6  # the learned policy alone, fresh maps


def test_per_level_budgets_and_thresholds():
    # open_door may not end before 10 updates' worth of steps (threshold 1.0 is unreachable
    # with a stochastic policy); give_key stops at its own, smaller step budget
    steps_per_update = SMALL["num_envs"] * SMALL["rollout_ticks"]
    cfg = TrainConfig(**(SMALL | {"max_steps_per_level": 10 * steps_per_update, "threshold": 1.0,
                                   "levels": {"give_key": {"max_steps_per_level": 4 * steps_per_update}}}))
    res = run(make_keydoor(), cfg, [0], progress=False)
    steps = {lvl["template"]: lvl["env_steps"][0] for lvl in res["levels"]}
    per_chunk = steps_per_update * SMALL["updates_per_chunk"]
    assert steps == {"open_door": 3 * per_chunk, "give_key": per_chunk}


def test_per_level_overrides_are_checked():
    with pytest.raises(ConfigError, match="unknown field"):
        TrainConfig(levels={"give_key": {"num_envs": 8}})
    with pytest.raises(ConfigError, match="threshold"):
        TrainConfig(levels={"give_key": {"threshold": 2.0}})
    with pytest.raises(ConfigError, match="does not train"):
        run(make_keydoor(), TrainConfig(**(SMALL | {"levels": {"give_kee": {"threshold": 0.5}}})), [0],
            progress=False)
    with pytest.raises(ConfigError, match="max_steps_per_level"):
        TrainConfig(max_steps_per_level=-1)


def test_continue_episodes_changes_where_levels_start():
    cfg = TrainConfig(**(SMALL | {"max_episodes_per_level": 300}))
    reset = run(make_keydoor(), cfg, [0], progress=False)
    going_on = run(make_keydoor(), cfg.replace(continue_episodes=True), [0], progress=False)
    assert [l["template"] for l in going_on["levels"]] == ["open_door", "give_key"]
    assert going_on["levels"][1] != reset["levels"][1]  # give_key sees other start states
    with pytest.raises(ConfigError, match="continue_episodes"):
        TrainConfig(continue_episodes="yes")
