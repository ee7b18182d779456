"""Checkpoints a resume can trust: every step carries a manifest of checksums that a resume
verifies, the previous good step is kept and can be resumed (``--resume-from``), a step
is found without ``latest.json``, and a host state that cannot belong to the run's plan
is refused naming the step."""
from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from hier_env import make_keydoor  # noqa: E402
from smjax.train import TrainConfig  # noqa: E402
from smjax.train import checkpoint as ckpt  # noqa: E402
from smjax.train.run import run  # noqa: E402

TINY = dict(num_envs=8, rollout_ticks=8, updates_per_chunk=2, max_episodes_per_level=300,
            success_window=32, gate_envs=8, eval_envs=8, checkpoint_every=0.0,
            finetune_max_episodes=100, finetune_turn_episodes=50)


def _arrays(x: float) -> dict:
    return {"a": np.full((64,), x, np.float32), "b": np.arange(4, dtype=np.int32)}


def _meta() -> dict:
    return {"run": {"seeds": [0]}, "host": {"stage": [0]}, "format": 5}


def _largest_file(step: Path) -> Path:
    files = [p for p in step.rglob("*") if p.is_file() and p.name != "smjax-manifest.json"]
    return max(files, key=lambda p: p.stat().st_size)


def _flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def test_the_previous_step_is_kept_and_a_flipped_byte_is_refused(tmp_path):
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    ckpt.save_checkpoint(tmp_path, 2, _arrays(2.0), _meta())
    root = ckpt.checkpoint_dir(tmp_path)
    assert {p.name for p in root.iterdir() if p.is_dir()} == {"step-1", "step-2"}
    _flip_byte(_largest_file(root / "step-2"))
    with pytest.raises(ckpt.CheckpointError, match="step-2 .* is corrupt .*--resume-from step-1"):
        ckpt.load_arrays(tmp_path, _arrays(0.0))
    restored = ckpt.load_arrays(tmp_path, _arrays(0.0), step="step-1")
    np.testing.assert_array_equal(restored["a"], np.full((64,), 1.0))


def test_a_step_is_found_without_latest_json(tmp_path):
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    ckpt.save_checkpoint(tmp_path, 2, _arrays(2.0), _meta())
    (ckpt.checkpoint_dir(tmp_path) / ckpt.LATEST).unlink()
    info = ckpt.load_meta(tmp_path)
    assert info["path"] == "step-2" and info["meta"] == _meta()
    np.testing.assert_array_equal(ckpt.load_arrays(tmp_path, _arrays(0.0))["a"], np.full((64,), 2.0))


def test_an_edited_latest_json_is_refused(tmp_path):
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    latest = ckpt.checkpoint_dir(tmp_path) / ckpt.LATEST
    info = json.loads(latest.read_text())
    info["meta"]["host"]["stage"] = [7]
    latest.write_text(json.dumps(info))
    with pytest.raises(ckpt.CheckpointError, match="does not match the manifest of step-1"):
        ckpt.load_meta(tmp_path)


def test_a_deleted_manifest_is_corruption(tmp_path):
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    (ckpt.checkpoint_dir(tmp_path) / "step-1" / "smjax-manifest.json").unlink()
    with pytest.raises(ckpt.CheckpointError, match="manifest is missing or unreadable.*--overwrite"):
        ckpt.load_arrays(tmp_path, _arrays(0.0))


def test_an_unknown_step_is_named_with_the_steps_kept(tmp_path):
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    with pytest.raises(ckpt.CheckpointError, match="step-9 .*steps there: step-1"):
        ckpt.load_meta(tmp_path, "step-9")


def _edit_host(out: Path, edit) -> None:
    """Rewrite the latest step's host state consistently (latest.json and its manifest),
    as a damaged but self-consistent checkpoint would be."""
    info = ckpt.load_meta(out)
    edit(info["meta"]["host"])
    step = ckpt.checkpoint_dir(out) / info["path"]
    manifest = json.loads((step / "smjax-manifest.json").read_text())
    manifest["meta"] = info["meta"]
    (step / "smjax-manifest.json").write_text(json.dumps(manifest))
    (ckpt.checkpoint_dir(out) / ckpt.LATEST).write_text(json.dumps(info))


@pytest.mark.slow
def test_a_host_state_outside_the_plan_is_refused(tmp_path):
    trained = tmp_path / "run"
    cfg = TrainConfig(**(TINY | {"max_episodes_per_level": 64}))
    run(make_keydoor(), cfg, [0], trained, progress=False)
    for k, (edit, needle) in enumerate([
            (lambda h: h.__setitem__("stage", [99]), "stage 99 is outside the plan"),
            (lambda h: h.__setitem__("chunks", -3), "chunks = -3"),
            (lambda h: h["episodes"].__setitem__(0, -5), r"episodes\[0\] = -5")]):
        out = tmp_path / f"copy-{k}"
        shutil.copytree(trained, out)
        _edit_host(out, edit)
        with pytest.raises(ckpt.CheckpointError, match=f"cannot belong to this run: .*{needle}"):
            run(make_keydoor(), cfg, [0], out, progress=False, resume=True)


@pytest.mark.slow
def test_a_failed_evaluation_keeps_the_trained_state_and_results_follow_on_resume(
        tmp_path, monkeypatch):
    from smjax.train.loop import HierarchyTrainer

    out = tmp_path / "run"
    cfg = TrainConfig(**(TINY | {"max_episodes_per_level": 64, "finetune": "off"}))

    def broken(self, t_start):
        raise RuntimeError("evaluation failed")

    with monkeypatch.context() as m:
        m.setattr(HierarchyTrainer, "evaluate", broken)
        with pytest.raises(RuntimeError, match="evaluation failed"):
            run(make_keydoor(), cfg, [0], out, progress=False)
    assert ckpt.load_meta(out)["meta"]["trained"] and not (out / "results.json").exists()
    # an evaluation-only setting may change when the run's training is done
    run(make_keydoor(), cfg.replace(eval_max_ticks=500), [0], out, progress=False, resume=True)
    assert (out / "results.json").exists()
