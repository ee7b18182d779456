"""The config's typed sections: one table maps them to the flat fields every run records."""
from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smjax.train.config import ConfigError, TrainConfig, resolve_config
from smjax.train.sections import SECTIONS, Evaluation, FineTuning, Run

FLAT_VALUES = {"finetune_threshold": 0.7, "finetune_mode": "turns", "finetune_max_episodes": 900,
               "finetune_plateau_episodes": 0, "finetune_agent": {"learning_rate": 1e-4},
               "gate_envs": 32, "eval_max_ticks": 300, "gate": False}


def test_every_section_field_names_a_config_field_once():
    fields = {f.name for f in dataclasses.fields(TrainConfig)}
    flat = [name for section in SECTIONS.values() for name in section.values()]
    assert set(flat) <= fields and len(set(flat)) == len(flat)
    assert set(SECTIONS["evaluation"]) == {f.name for f in dataclasses.fields(Evaluation)}
    assert set(SECTIONS["run"]) == {f.name for f in dataclasses.fields(Run)}


def test_the_sections_hold_the_config_values():
    cfg = TrainConfig(**FLAT_VALUES, finetune_side_cost_weight=0.5)
    ft, ev = cfg.fine_tuning, cfg.evaluation
    assert isinstance(ft, FineTuning) and isinstance(ev, Evaluation)
    assert (ft.threshold, ft.mode, ft.max_episodes, ft.plateau_episodes) == (0.7, "turns", 900, 0)
    assert ft.agent == {"learning_rate": 1e-4} and ft.side_cost == 0.5
    assert TrainConfig(finetune_side_cost=False).fine_tuning.side_cost == 0.0
    assert (ev.gate, ev.gate_envs, ev.eval_max_ticks) == (False, 32, 300)
    assert TrainConfig().fine_tuning.on and not TrainConfig(method="bottom-up").fine_tuning.on
    assert cfg.replace(finetune_threshold=0.5).fine_tuning.threshold == 0.5


def test_the_run_section_resolves_the_rollout_shape():
    run = TrainConfig(num_envs=16, rollout_ticks=8, updates_per_chunk=3, tensorboard=True).run
    assert isinstance(run, Run) and run.tensorboard
    assert (run.pool_size, run.steps_per_update, run.steps_per_chunk) == (16, 128, 384)
    assert TrainConfig(num_envs=16, reset_pool=0).run.pool_size == 0
    assert TrainConfig(num_envs=16, reset_pool=4).run.pool_size == 4
    assert (resolve_config(sets={"run.num_envs": "16", "run.checkpoint_every": "5"})
            == TrainConfig(num_envs=16, checkpoint_every=5.0))
    with pytest.raises(ConfigError, match="given twice"):
        TrainConfig.from_dict({"run": {"num_envs": 8}, "num_envs": 16})


def test_a_file_may_name_fields_by_section(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("fine_tuning:\n  threshold: 0.7\n  mode: turns\n  max_episodes: 900\n"
                    "  plateau_episodes: 0\n  agent: {learning_rate: 1.0e-4}\n"
                    "evaluation: {gate_envs: 32, eval_max_ticks: 300, gate: false}\n")
    assert resolve_config(file=path) == TrainConfig(**FLAT_VALUES)
    sets = {"fine_tuning.threshold": "0.7", "evaluation.gate_envs": "32"}
    assert resolve_config(sets=sets) == TrainConfig(finetune_threshold=0.7, gate_envs=32)


def test_section_errors_name_the_fields():
    with pytest.raises(ConfigError, match="has no field 'treshold'.*threshold"):
        TrainConfig.from_dict({"fine_tuning": {"treshold": 0.5}})
    with pytest.raises(ConfigError, match="given twice"):
        TrainConfig.from_dict({"fine_tuning": {"threshold": 0.5}, "finetune_threshold": 0.6})
    with pytest.raises(ConfigError, match="must be a mapping"):
        TrainConfig.from_dict({"evaluation": 3})
    with pytest.raises(ConfigError, match="evaluation.*no field 'envs'"):
        resolve_config(sets={"evaluation.envs": "4"})


@settings(max_examples=25, deadline=None)
@given(threshold=st.floats(0.05, 1.0), envs=st.integers(1, 512), gate=st.booleans(),
       episodes=st.integers(1, 50_000))
def test_sections_and_flat_fields_make_the_same_config(threshold, envs, gate, episodes):
    nested = {"fine_tuning": {"threshold": threshold, "max_episodes": episodes},
              "evaluation": {"gate_envs": envs, "gate": gate}}
    flat = {"finetune_threshold": threshold, "finetune_max_episodes": episodes,
            "gate_envs": envs, "gate": gate}
    cfg = TrainConfig.from_dict(nested)
    assert cfg == TrainConfig.from_dict(flat) and cfg.to_dict() == TrainConfig(**flat).to_dict()
    assert cfg.fine_tuning.threshold == threshold and cfg.evaluation.gate_envs == envs


def test_fine_tuning_enabled_reads_true_and_false_as_on_and_off(tmp_path):
    # YAML 1.1 reads ``enabled: off`` as false: it must mean "off", not be refused
    path = tmp_path / "off.yaml"
    path.write_text("fine_tuning:\n  enabled: off\n")
    assert resolve_config(file=path).finetune == "off"
    assert not resolve_config(file=path).fine_tuning.on
    assert resolve_config(sets={"fine_tuning.enabled": True}).finetune == "on"
    assert TrainConfig(finetune=False) == TrainConfig(finetune="off")
    with pytest.raises(ConfigError, match="'finetune'.*one of"):
        TrainConfig(finetune="maybe")
