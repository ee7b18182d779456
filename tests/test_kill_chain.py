"""SIGKILL at random instants, across a level and fine-tuning: every chain of resumes must
end with the very results of an uninterrupted run (only timings differ)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

TINY = ["craft/get_wood", "--quiet", "--num-envs", "8", "--set", "rollout_ticks=8",
        "--set", "updates_per_chunk=2", "--max-episodes", "300", "--set", "success_window=32",
        "--set", "gate_envs=8", "--set", "eval_envs=8", "--set", "checkpoint_every=0",
        "--finetune", "on", "--finetune-episodes", "100", "--set", "finetune_turn_episodes=50"]
KILLS = 50


def _start(out: Path, fresh: bool) -> subprocess.Popen:
    where = ["--out", str(out), "--overwrite"] if fresh else ["--resume", str(out)]
    return subprocess.Popen([sys.executable, "-m", "smjax", "train", *TINY, *where],
                            env=dict(os.environ, JAX_PLATFORMS="cpu"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _results(out: Path):
    """results.json without its timings (they differ between any two runs)."""
    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if "seconds" not in k}
        return [strip(v) for v in x] if isinstance(x, list) else x

    return strip(json.loads((out / "results.json").read_text()))


def _kill_at_random(proc: subprocess.Popen, latest: Path, rng) -> bool:
    """Kill ``proc`` at a random instant (mostly once it has saved again); False if it
    ended first."""
    before = latest.read_text() if latest.exists() else None
    if rng.random() < 0.2:  # during start-up or compile now and then
        time.sleep(rng.uniform(0.0, 8.0))
    else:
        deadline = time.time() + 300
        while proc.poll() is None and time.time() < deadline:
            if latest.exists() and latest.read_text() != before:
                break
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 1.5))
    if proc.poll() is not None:
        return False
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    return True


@pytest.mark.slow
def test_sigkills_at_random_instants_resume_to_the_uninterrupted_results(tmp_path):
    ref = tmp_path / "ref"
    assert _start(ref, fresh=True).wait() == 0
    expected = _results(ref)
    rng = np.random.default_rng(44)
    kills, chains = 0, 0
    while kills < KILLS:
        out = tmp_path / f"chain{chains}"
        latest = out / "checkpoints" / "latest.json"
        while True:
            proc = _start(out, fresh=not latest.exists())
            if _kill_at_random(proc, latest, rng):
                kills += 1
                print(f"kill {kills} (chain {chains}, checkpoint "
                      f"{json.loads(latest.read_text())['path'] if latest.exists() else 'none'})",
                      flush=True)
                continue
            assert proc.returncode == 0, proc.stderr.read()[-2000:]
            break
        assert _results(out) == expected, f"chain {chains} after {kills} kills differs"
        chains += 1
    print(f"{kills} SIGKILLs over {chains} chains; every chain's results equal the "
          f"uninterrupted run's")
