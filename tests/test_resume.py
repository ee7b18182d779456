"""Checkpoint and resume: a run killed with SIGKILL mid-level and resumed gives the same
results as an uninterrupted run, and so does one lost right after a level-boundary
checkpoint; a different config is refused, naming the fields."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _helpers import MachineLost, lose_machine_after_save
from hier_env import make_keydoor
from smjax.train import ConfigError, TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.run import run

CFG = dict(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=1500,
           success_window=64, gate_envs=32, eval_envs=32, checkpoint_every=2.0,
           finetune_max_episodes=400, finetune_turn_episodes=150)
SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
from _helpers import MachineLost, lose_machine_after_save
from hier_env import make_keydoor
from smjax.train import TrainConfig
from smjax.train.run import run
run(make_keydoor(), TrainConfig(**{cfg!r}), [0, 1], {out!r}, progress=False, resume={resume!r})
"""


def _strip_timing(res: dict) -> dict:
    return {k: v for k, v in res.items() if k not in ("wall_seconds", "compile_seconds", "_raw")}


def _start(out: Path, resume: bool) -> subprocess.Popen:
    code = SCRIPT.format(tests=str(Path(__file__).parent), cfg=CFG, out=str(out), resume=resume)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    return subprocess.Popen([sys.executable, "-c", code], env=env)


def test_sigkill_then_resume_equals_uninterrupted(tmp_path):
    straight = run(make_keydoor(), TrainConfig(**CFG), [0, 1], tmp_path / "straight", progress=False)
    out = tmp_path / "killed"
    proc = _start(out, resume=False)
    latest = out / "checkpoints" / "latest.json"
    deadline = time.time() + 240
    # wait until a few chunks are checkpointed, then kill without warning mid-level
    while time.time() < deadline:
        if latest.exists() and json.loads(latest.read_text())["step"] >= 3:
            break
        if proc.poll() is not None:
            pytest.fail("training finished before it could be killed; lengthen the run")
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "results.json").exists()
    resumed = run(make_keydoor(), TrainConfig(**CFG), [0, 1], out, progress=False, resume=True)
    assert _strip_timing(resumed) == _strip_timing(straight)
    on_disk = json.loads((out / "results.json").read_text())
    assert on_disk["levels"] == straight["levels"]
    # the refusals are checked on this finished run (a run of their own would train again)
    _resume_with_different_config_is_refused(out, tmp_path / "empty")


def _resume_with_different_config_is_refused(out, empty):
    """``out`` holds a checkpointed run of ``CFG`` with seeds [0, 1]."""
    other = TrainConfig(**(CFG | {"gamma": 0.95, "num_envs": 8}))
    with pytest.raises(ConfigError, match=r"differs in .*gamma.*num_envs"):
        run(make_keydoor(), other, [0, 1], out, progress=False, resume=True)
    with pytest.raises(ConfigError, match="seeds"):
        run(make_keydoor(), TrainConfig(**CFG), [0], out, progress=False, resume=True)
    with pytest.raises(FileExistsError, match="already holds"):
        run(make_keydoor(), TrainConfig(**CFG), [0], out, progress=False)
    with pytest.raises(FileNotFoundError, match="nothing to resume"):
        run(make_keydoor(), TrainConfig(**CFG), [0], empty, progress=False, resume=True)


def test_a_level_boundary_checkpoint_holds_the_next_level_and_resumes_exactly(tmp_path, monkeypatch):
    # checkpoints only at level boundaries (what a run that moves between machines uses)
    cfg = TrainConfig(**(CFG | {"max_episodes_per_level": 300, "checkpoint_every": 1e9}))
    straight = run(make_keydoor(), cfg, [0, 1], tmp_path / "straight", progress=False)
    assert len(straight["levels"]) >= 2
    # a seed has just finished its first level
    lose_machine_after_save(monkeypatch, lambda trainer: max(trainer.state.stage) == 1)
    out = tmp_path / "moved"
    with pytest.raises(MachineLost):
        run(make_keydoor(), cfg, [0, 1], out, progress=False)
    monkeypatch.undo()
    host = ckpt.load_meta(out)["meta"]["host"]
    # the checkpoint holds the start of level 2 for the seed that finished level 1: its
    # learner is fresh and level 1 is in the bank (the other seed is still in level 1)
    moved = [s for s in range(2) if host["stage"][s] == 1]
    assert moved and host["started"] == [True, True]
    for s in moved:
        assert host["episodes"][s] == 0 and host["env_steps"][s] == 0
        assert host["levels"][0]["episodes"][s] == straight["levels"][0]["episodes"][s]
    # settings that do not change results are not part of the run's identity: a resume may
    # change them, also of a checkpoint written before they left it (edited to look like one)
    latest = ckpt.checkpoint_dir(out) / "latest.json"
    index = json.loads(latest.read_text())
    assert "checkpoint_every" not in index["meta"]["run"]
    assert index["meta"].pop("settings") == {"tensorboard": False, "checkpoint_every": 1e9}
    index["meta"]["run"] |= {"tensorboard": False, "checkpoint_every": 1e9}
    # (a checkpoint of that time had no manifest: format 4)
    index["meta"]["format"] = 4
    (latest.parent / index["path"] / "smjax-manifest.json").unlink()
    latest.write_text(json.dumps(index))
    changed = cfg.replace(tensorboard=True, checkpoint_every=1e8)
    resumed = run(make_keydoor(), changed, [0, 1], out, progress=False, resume=True)
    assert _strip_timing(resumed) | {"config": None} == _strip_timing(straight) | {"config": None}
    assert resumed["config"] == straight["config"] | {"tensorboard": True, "checkpoint_every": 1e8}
    assert list((out / "tensorboard").glob("events.out.tfevents.*"))


def test_arrays_of_another_layout_are_refused_as_such_not_as_corrupt(tmp_path):
    """A checkpoint written by code whose trainer holds other arrays (e.g. a learner state
    with more hyper-parameters) is intact: the error says so and does not suggest deleting it."""
    import numpy as np

    ckpt.save_checkpoint(tmp_path, 1, {"a": np.zeros(3), "b": np.ones(2)}, {"run": {}, "host": {}})
    with pytest.raises(ckpt.CheckpointError, match="other arrays than this smjax"):
        ckpt.load_arrays(tmp_path, {"a": np.zeros(3), "b": np.ones(2), "c": np.ones(1)})
    with pytest.raises(ckpt.CheckpointError, match="other arrays than this smjax"):
        ckpt.load_arrays(tmp_path, {"a": np.zeros(3)})
    restored = ckpt.load_arrays(tmp_path, {"a": np.zeros(3), "b": np.zeros(2)})
    assert float(restored["b"].sum()) == 2.0  # the same layout still restores


def test_a_checkpoint_from_before_a_new_config_field_resumes_unless_it_differs(monkeypatch):
    # a checkpoint written before ``level_side_cost_weight`` existed lacks it: it takes the
    # default (which keeps the older behaviour), so the run resumes; a real difference in
    # any field is still refused, by name
    from smjax.train.run import check_resumable, run_identity

    cfg = TrainConfig(**CFG)
    identity = run_identity("keydoor", cfg, [0, 1], {})
    old = {k: v for k, v in identity.items() if k != "level_side_cost_weight"}
    monkeypatch.setattr(ckpt, "shared_meta", lambda out, step=None: {"meta": {"run": old}})
    assert check_resumable("some/dir", identity)
    changed = run_identity("keydoor", cfg.replace(level_side_cost_weight=1.0), [0, 1], {})
    with pytest.raises(ConfigError, match="level_side_cost_weight: checkpoint 0.0 vs now 1.0"):
        check_resumable("some/dir", changed)
    # a field whose default changed what runs do (fine-tuning turns that keep their
    # episodes): a checkpoint without it ran the old way, so it resumes only that way
    old = {k: v for k, v in identity.items() if k != "finetune_continue_episodes"}
    monkeypatch.setattr(ckpt, "shared_meta", lambda out, step=None: {"meta": {"run": old}})
    with pytest.raises(ConfigError, match="finetune_continue_episodes: checkpoint False vs now True"):
        check_resumable("some/dir", identity)
    legacy = run_identity("keydoor", cfg.replace(finetune_continue_episodes=False), [0, 1], {})
    assert check_resumable("some/dir", legacy)


def test_checkpoint_formats_this_smjax_cannot_read_are_refused_by_name(tmp_path):
    # format 2 (windows as host lists) is migrated on restore (test_finetune resumes one);
    # older ones and newer ones are refused, saying which
    from smjax.train.hooks import CHECKPOINT_FORMAT

    host = {"finetune": {}}
    for version in range(2, CHECKPOINT_FORMAT + 1):
        assert ckpt.check_format(tmp_path, {"format": version, "host": host}, 2,
                                 CHECKPOINT_FORMAT) == version
    for meta, which in (({"host": host}, "an older"), ({"format": 2, "host": {}}, "an older"),
                        ({"format": CHECKPOINT_FORMAT + 1, "host": host}, "a newer")):
        with pytest.raises(ckpt.CheckpointError, match=f"written by {which} smjax"):
            ckpt.check_format(tmp_path, meta, 2, CHECKPOINT_FORMAT)


@pytest.mark.parametrize("failing", ["build_results", "write_results"])
def test_an_error_writing_results_loses_no_training(tmp_path, monkeypatch, failing):
    """Training done, then results fail to build or write: the trained state is already
    checkpointed, the error says how to get the results, and resuming writes them
    without training again."""
    from smjax.train.results import ResultsError

    # where each is looked up: the run builds the results, its results hook writes them
    # (sys.modules: the package exports the function run too)
    owner = {"build_results": sys.modules["smjax.train.run"],
             "write_results": sys.modules["smjax.train.results"]}[failing]

    cfg = TrainConfig(method="flat", num_envs=16, rollout_ticks=8, updates_per_chunk=2,
                      max_episodes_per_level=60, success_window=16, eval_envs=16,
                      checkpoint_every=0.0)
    out = tmp_path / "run"

    def broken(*args, **kwargs):
        raise AttributeError("module 'smjax' has no attribute '__version__'")

    monkeypatch.setattr(owner, failing, broken)
    with pytest.raises(ResultsError, match=r"--resume") as err:
        run(make_keydoor(), cfg, [0], out, progress=False)
    assert str(out) in str(err.value) and "__version__" in str(err.value)
    assert not (out / "results.json").exists()
    info = ckpt.load_meta(out)
    assert info is not None and info["meta"]["trained"] is True
    monkeypatch.undo()
    res = run(make_keydoor(), cfg, [0], out, progress=False, resume=True)
    saved = json.loads((out / "results.json").read_text())
    assert saved["levels"] == res["levels"] and saved["final_success"] == res["final_success"]
