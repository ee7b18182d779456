"""Refusals that come before any XLA program is compiled: making a built-in task runs none,
so a bad hierarchy, a resume of a damaged or foreign checkpoint, joint fine-tuning of a
recurrent policy and ``render --policy`` of such a run are refused in one line whatever
the machine's speed."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np
import pytest

from _helpers import cli_answer
from smjax.train import checkpoint as ckpt
from smjax.train.config import resolve_config
from smjax.train.run import run_identity

TASK = "craft/make_stick"

COUNT_COMPILES = """
import jax, smjax
compiles = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, *a, **k: compiles.append(1)
    if event == "/jax/core/compile/backend_compile_duration" else None)
for task in ("craft/get_gem", "fetch/stack1", "football/11v11_easy"):
    smjax.make(task)
smjax.make("craft/get_gem", max_steps=50)
print(len(compiles))
"""


def test_importing_and_making_builtin_tasks_compiles_nothing():
    """(A fresh process: a package's module constants are made once, at its first import.)"""
    done = subprocess.run([sys.executable, "-c", COUNT_COMPILES], capture_output=True, text=True,
                          env=dict(os.environ, JAX_PLATFORMS="cpu"), timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-1] == "0", done.stdout


def _checkpoint(out: Path, stage: int = 0, chunks: int = 0) -> Path:
    """A checkpoint of a default ``smjax train TASK --resume out``'s run, its host state
    without counters (refused as damaged unless an earlier check refuses it) and arrays
    that stand in for the trainer's: nothing gets as far as loading them."""
    identity = run_identity(TASK, resolve_config(), [0], {})
    host = {"stage": [stage], "started": [False], "levels": [], "curves": [], "finetune": {},
            "compile_seconds": 0.0, "wall_seconds": 0.0, "chunks": chunks}
    meta = {"run": identity, "host": host, "settings": {}, "format": 5}
    ckpt.save_checkpoint(out, 1, {"a": np.arange(4096, dtype=np.float32)}, meta)
    return ckpt.checkpoint_dir(out) / "step-1"


def _flip_a_byte(step: Path) -> None:
    data = max((p for p in step.rglob("*") if p.is_file() and "manifest" not in p.name),
               key=lambda p: p.stat().st_size)
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    data.write_bytes(bytes(raw))


@pytest.mark.parametrize("damage, needle", [
    (dict(flip=True), "step-1 in"), (dict(stage=99), "stage 99 is outside the plan"),
    (dict(chunks=-5), "chunks = -5 is not a count"),
    (dict(), "is damaged: its host state lacks the counter episodes")])
def test_a_damaged_checkpoint_is_refused_before_compiling(tmp_path, capsys, damage, needle):
    step = _checkpoint(tmp_path / "r", damage.get("stage", 0), damage.get("chunks", 0))
    if damage.get("flip"):
        _flip_a_byte(step)
    code, err = cli_answer(["train", TASK, "--quiet", "--resume", str(tmp_path / "r")], capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err
    if damage.get("flip"):
        assert "is corrupt" in err


def test_render_of_an_unfinished_run_is_refused_before_compiling(tmp_path, capsys):
    # a run stopped before its end has a checkpoint but no saved policy yet
    run_dir = tmp_path / "r"
    _checkpoint(run_dir)
    render = ["render", TASK, "--policy", str(run_dir), "--out", str(tmp_path / "e.gif")]
    code, err = cli_answer(render, capsys)
    assert code == 2 and "holds no saved policy" in err and "resume" in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "e.gif").exists()


@pytest.mark.parametrize("extra, needle", [
    (["--agent", "recurrent_size=8"], "finetune_mode' = 'joint'"),
    (["--hierarchy", "nosuch"], "unknown hierarchy 'nosuch'"),
    (["--set", "reset_pool=1048576", "--seeds", "64"], "batch too large")])
def test_refusals_after_making_the_task_compile_nothing(tmp_path, capsys, monkeypatch, extra,
                                                        needle):
    from smjax.train import memory

    monkeypatch.setattr(memory, "available_bytes", lambda: 2 * 2**30)
    code, err = cli_answer(["train", TASK, "--quiet", "--out", str(tmp_path / "r"), *extra], capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err


def test_a_resume_that_differs_is_refused_before_compiling(tmp_path, capsys):
    _checkpoint(tmp_path / "r")
    code, err = cli_answer(["train", TASK, "--quiet", "--resume", str(tmp_path / "r"),
                            "--set", "gamma=0.5"], capsys)
    assert code == 2 and "differs in gamma" in err, err


def test_an_error_never_repeats_a_huge_value(tmp_path, capsys):
    code, err = cli_answer(["train", TASK, "--quiet", "--out", str(tmp_path / "r"),
                            "--set", "hierarchy=" + "h" * 200_000], capsys)
    assert code == 2 and "unknown hierarchy" in err and len(err) < 600, err[:300]
    # a message that repeats a value whole anyway is cut where the CLI prints it
    code, err = cli_answer(["train", "craft/" + "x" * 100_000, "--out", str(tmp_path / "r")], capsys)
    assert code == 2 and "unknown task" in err and len(err) < 2_100, len(err)
