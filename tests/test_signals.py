"""SIGTERM (what schedulers send before they kill a job) ends a run as Ctrl-C does: promptly,
lock released, and the message says how to resume."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from smjax.train.outdir import LOCK_NAME

SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
from hier_env import make_keydoor
from smjax.core.registry import register
from smjax.cli import entry
register("test/keydoor", lambda: make_keydoor())
sys.exit(entry(["train", "test/keydoor", "--out", {out!r}, "--quiet", "--set", "num_envs=8",
               "--set", "rollout_ticks=8", "--set", "checkpoint_every=0",
               "--set", "max_episodes_per_level=10000000", "--set", "threshold=1.0",
               "--set", "success_window=10000"]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_ends_the_run_promptly_with_the_resume_command(tmp_path, sig):
    out = tmp_path / "run"
    code = SCRIPT.format(tests=str(Path(__file__).parent), out=str(out))
    proc = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE, text=True,
                            stdout=subprocess.DEVNULL, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    try:
        deadline = time.time() + 120
        while not (out / "checkpoints" / "latest.json").exists() and time.time() < deadline:
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.2)
        t0 = time.perf_counter()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
        assert time.perf_counter() - t0 < 15
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert f"resume with: smjax train test/keydoor --resume {out}" in err
    assert not (out / LOCK_NAME).exists()
