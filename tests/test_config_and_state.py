"""resolve_config merges a run's configuration sources in one order; the trainer's host
state round-trips through the checkpoint's JSON layout (format 2). Fast: nothing compiles."""
import json

import pytest

from smjax.train import ConfigError, TrainConfig
from smjax.train.config import RUN_SETTINGS, resolve_config
from smjax.train.plans import LevelPlan
from smjax.train.run import run_identity
from smjax.train.state import TrainerState, append_window


def test_sources_override_in_order(tmp_path):
    saved = {"task": "craft/get_wood", "seeds": [0], "num_envs": 8, "threshold": 0.5,
             "gamma": 0.9, "agent": {"learning_rate": 1e-3, "ent_coef": 0.1}}
    file = tmp_path / "cfg.yaml"
    file.write_text("threshold: 0.6\ngamma: 0.95\n")
    cfg = resolve_config(saved_run=saved, file=file, sets={"gamma": 0.97},
                         agent={"ent_coef": "0.2"})
    assert (cfg.num_envs, cfg.threshold, cfg.gamma) == (8, 0.6, 0.97)
    assert cfg.agent == {"learning_rate": 1e-3, "ent_coef": 0.2}  # merged, parsed
    assert resolve_config() == TrainConfig()
    base = TrainConfig(num_envs=4, agent={"hidden": (16, 16)})
    assert resolve_config(base).agent == {"hidden": [16, 16]}  # as JSON stores it
    assert resolve_config(base, sets={"threshold": 0.7}).num_envs == 4
    with pytest.raises(ConfigError, match="--set gamma=0.5"):
        resolve_config(agent={"gamma": 0.5})


def test_settings_that_do_not_change_results_are_not_the_run_identity():
    identity = run_identity("craft/get_wood", TrainConfig(tensorboard=True), [0], {})
    assert not set(RUN_SETTINGS) & set(identity)
    assert run_identity("craft/get_wood", TrainConfig(checkpoint_every=1.0), [0], {}) == \
        run_identity("craft/get_wood", TrainConfig(), [0], {})


def test_host_state_round_trips_through_the_checkpoint_layout():
    plans = [LevelPlan("root", 0, 0, 2), LevelPlan("get_wood", 1, 0, 1)]
    st = TrainerState.new(plans, 2)
    st.level[1].count([3, 4], [2.0, 1.0], [3, 2], 64, window=4)
    st.level[1].record_gate({"success": [0.0, 0.75], "env_steps": [0, 99]}, 1, 12)
    st.finish_level(1)
    st.finetune[0].turns.append({"template": "root", "episodes": 5, "running_success": None})
    host = json.loads(json.dumps(st.to_json()))
    assert host["stage"] == [0, 1] and host["episodes"] == [0, 7]
    assert host["levels"][0]["gate_success"] == [None, 0.75]
    assert host["finetune"]["turns"] == [[{"template": "root", "episodes": 5,
                                           "running_success": None}], []]
    assert TrainerState.from_json(host) == st


def test_the_window_averages_whole_batches_of_at_least_its_length():
    history = []
    assert append_window(history, 1.0, 2, 4) is None
    assert append_window(history, 0.0, 0, 4) is None  # no episodes: nothing added
    assert append_window(history, 3.0, 3, 4) == 4.0 / 5
    assert append_window(history, 4.0, 4, 4) == 1.0 and history == [[4.0, 4]]
