"""Every config value bounded before anything compiles, the same for the Python API, config
files and the command line: booleans are never numbers, numpy scalars of the right kind
are, every field has an upper bound, files with duplicate keys or aliases are refused,
and no error echoes a huge value."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np
import pytest

from _helpers import cli_answer
from smjax.train import TrainConfig
from smjax.train.config import ConfigError, read_config_file


def test_numpy_scalars_of_the_right_kind_are_accepted():
    cfg = TrainConfig(num_envs=np.int64(16), threshold=np.float32(0.5), gamma=np.float64(0.9))
    assert cfg.num_envs == 16 and type(cfg.num_envs) is int
    assert cfg.threshold == 0.5 and type(cfg.threshold) is float


@pytest.mark.parametrize("field, value", [
    ("threshold", True), ("gamma", True), ("checkpoint_every", float("inf")),
    ("eval_max_ticks", 2**31), ("gate_max_ticks", 3_000_000_000), ("success_window", 2**31),
    ("num_envs", 10**400), ("num_envs", np.bool_(True)), ("reset_pool", 50_000_000),
    ("max_episodes_per_level", True), ("finetune_plateau_gain", np.float32("nan")),
])
def test_out_of_range_or_wrongly_typed_values_are_refused(field, value):
    with pytest.raises(ConfigError, match=f"'{field}'"):
        TrainConfig(**{field: value})


@pytest.mark.parametrize("agent, needle", [
    ({"nosuch": 1}, "nosuch"), ({"num_minibatches": 100_000}, "num_minibatches"),
    ({"hidden_sizes": []}, "hidden_sizes"), ({"hidden_sizes": [65536, 65536]}, "hidden_sizes"),
])
def test_learner_settings_are_checked_with_the_config(agent, needle):
    with pytest.raises(ConfigError, match=needle):
        TrainConfig(agent=agent)


def test_finetune_agent_values_are_checked_by_the_learner():
    with pytest.raises(ConfigError, match="finetune_agent.*learning_rate"):
        TrainConfig(finetune_agent={"learning_rate": -1e-3})


def test_error_messages_never_echo_a_huge_value():
    with pytest.raises(ConfigError) as err:
        TrainConfig(num_envs=10**400)
    assert len(str(err.value)) < 300
    with pytest.raises(ConfigError) as err:
        TrainConfig.from_dict({"x" * 100_000: 1})
    assert len(str(err.value)) < 2000


@pytest.mark.parametrize("text, needle", [
    ("threshold: 0.5\nthreshold: 0.6\n", "given twice"),
    ("a: &a [1, 1]\nb: &b [*a, *a]\nagent: {hidden_sizes: *b}\n", "aliases"),
    ("levels: &x {}\nfinetune_agent: *x\n", "aliases"),
])
def test_yaml_duplicate_keys_and_aliases_are_refused(tmp_path, text, needle):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=needle):
        read_config_file(path)


def test_json_duplicate_keys_are_refused(tmp_path):
    path = tmp_path / "c.json"
    path.write_text('{"threshold": 0.5, "threshold": 0.6}')
    with pytest.raises(ConfigError, match="given twice"):
        read_config_file(path)


@pytest.mark.parametrize("extra, needle", [
    (["--set", "eval_max_ticks=2147483648"], "eval_max_ticks"),
    (["--set", "gate_max_ticks=3000000000"], "gate_max_ticks"),
    (["--set", "success_window=2147483648"], "success_window"),
    (["--agent", "num_minibatches=100000"], "num_minibatches"),
    (["--agent", "hidden_sizes=[]"], "hidden_sizes"),
    (["--set", 'finetune_agent={"learning_rate": -1}'], "learning_rate"),
    (["--set", 'levels={"a": {}, "a": {}}'], "given twice"),
    (["--set", " threshold=0.5"], "spaces"),
    (["--sweep", "agent.learning_rate=0.001,0.001"], "twice"),
    (["--sweep", "agent.learning_rate=" + ",".join(f"{k}e-5" for k in range(1, 80)),
      "--sweep", "agent.ent_coef=" + ",".join(f"{k}e-4" for k in range(1, 80))], "points"),
])
def test_bad_values_are_refused_by_the_cli_before_compiling(tmp_path, capsys, extra, needle):
    code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(tmp_path / "o"),
                      *extra], capsys)
    assert code == 2 and needle in err, err
    assert len(err.splitlines()) <= 2
