"""Refusals that come before any XLA program is compiled: making a built-in task runs none,
so a bad hierarchy, a resume of a damaged or foreign checkpoint, joint fine-tuning of a
recurrent policy and ``render --policy`` of such a run are refused in one line whatever
the machine's speed."""
from __future__ import annotations

import os
import subprocess
import sys

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import pytest

from _helpers import cli_answer

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


@pytest.mark.parametrize("extra, needle", [
    (["--hierarchy", "nosuch"], "unknown hierarchy 'nosuch'"),
    (["--set", "reset_pool=1048576", "--seeds", "64"], "batch too large")])
def test_refusals_after_making_the_task_compile_nothing(tmp_path, capsys, monkeypatch, extra,
                                                        needle):
    from smjax.train import memory

    monkeypatch.setattr(memory, "available_bytes", lambda: 2 * 2**30)
    code, err = cli_answer(["train", TASK, "--quiet", "--out", str(tmp_path / "r"), *extra], capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err
