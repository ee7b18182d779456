"""Checkpoint and resume: a run killed with SIGKILL mid-level and resumed gives the same
results as an uninterrupted run, and so does one lost right after a level-boundary
checkpoint; a different config is refused, naming the fields, and a checkpoint of
another format than this smjax's, naming both formats."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from _helpers import MachineLost, cli_answer, lose_machine_after_save, with_format
from hier_env import make_keydoor
from smjax.train import ConfigError, TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.run import run

CFG = dict(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=1500,
           success_window=64, gate_envs=32, eval_envs=32, checkpoint_every=2.0,
           finetune_max_episodes=128, finetune_turn_episodes=64)
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
    # change them
    meta = ckpt.load_meta(out)["meta"]
    assert "checkpoint_every" not in meta["run"] and "tensorboard" not in meta["run"]
    assert meta["settings"] == {"tensorboard": False, "checkpoint_every": 1e9}
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


def test_a_config_field_missing_from_a_checkpoint_compares_as_its_default(monkeypatch):
    # every field is compared: one the checkpoint's identity lacks as its default, so the
    # run resumes at the default and a value other than the default is refused, by name
    from smjax.train.run import check_resumable, run_identity

    cfg = TrainConfig(**CFG)
    identity = run_identity("keydoor", cfg, [0, 1], {})
    info = {"path": "step-1", "meta": {"format": ckpt.CHECKPOINT_FORMAT, "host": {}, "run": {}}}
    monkeypatch.setattr(ckpt, "shared_meta", lambda out, step=None: info)
    for field, other in (("level_side_cost_weight", 1.0), ("finetune_continue_episodes", False),
                         ("finetune_mode", "turns")):
        info["meta"]["run"] = {k: v for k, v in identity.items() if k != field}
        assert check_resumable("some/dir", identity)
        changed = run_identity("keydoor", cfg.replace(**{field: other}), [0, 1], {})
        with pytest.raises(ConfigError, match=f"{field}: checkpoint {identity[field]!r} vs "
                                              f"now {other!r}"):
            check_resumable("some/dir", changed)


def test_checkpoint_formats_this_smjax_cannot_read_are_refused_by_name(tmp_path, capsys):
    # this smjax resumes its own format alone: an older one (none recorded: format 1) or a
    # newer one is refused before anything compiles, in one line naming the directory, both
    # formats and what to do
    from smjax.train.state import TrainerState

    root = ckpt.checkpoint_dir(tmp_path)
    ckpt.check_format(tmp_path, {"path": "step-1", "meta": {"format": ckpt.CHECKPOINT_FORMAT}})
    host = TrainerState.new([], 1).to_json()
    meta = {"run": {"task": "craft/get_wood", "seeds": [0], "env_overrides": {}}, "host": host,
            "settings": {}, "format": ckpt.CHECKPOINT_FORMAT}
    ckpt.save_checkpoint(tmp_path, 1, {"a": np.zeros(3, np.float32)}, meta)
    for version, which in ((None, "1, written by an older"), (2, "2, written by an older"),
                           (4, "4, written by an older"),
                           (ckpt.CHECKPOINT_FORMAT + 1, f"{ckpt.CHECKPOINT_FORMAT + 1}, "
                                                        f"written by a newer")):
        with_format(tmp_path, version)
        said = (f"checkpoint step-1 in {root} is of format {which} smjax; this smjax resumes "
                f"format {ckpt.CHECKPOINT_FORMAT} only: resume it with the smjax version that "
                f"wrote it, or train again in another directory")
        with pytest.raises(ckpt.CheckpointError) as refused:
            ckpt.shared_meta(tmp_path)
        assert str(refused.value) == said
        code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--resume", str(tmp_path)],
                               capsys)
        assert code == 2 and said in err and len(err.strip().splitlines()) == 1, err
    # (the latest step's, also where it is read from its manifest alone)
    (root / ckpt.LATEST).unlink()
    with pytest.raises(ckpt.CheckpointError, match="is of format 6"):
        ckpt.shared_meta(tmp_path, "step-1")


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


def test_a_trained_run_resumed_with_every_evaluation_mode(tmp_path):
    """The final evaluation runs the run's own mode; resuming the trained run with
    ``eval_policies`` "all" evaluates every mode without training again."""
    from smjax.options.episodes import EVAL_TEMPERATURES

    cfg = TrainConfig(method="flat", num_envs=16, rollout_ticks=8, updates_per_chunk=2,
                      max_episodes_per_level=60, success_window=16, eval_envs=16,
                      checkpoint_every=0.0)
    out = tmp_path / "run"
    first = run(make_keydoor(), cfg, [0], out, progress=False)
    assert list(first["final_success_by_policy"]) == ["sample"]
    again = run(make_keydoor(), cfg.replace(eval_policies="all"), [0], out, progress=False,
                resume=True)
    assert set(again["final_success_by_policy"]) == set(EVAL_TEMPERATURES)
    assert again["final_success"] == first["final_success"]
    assert again["levels"] == first["levels"]
