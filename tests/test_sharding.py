"""Seeds sharded over (virtual CPU) devices give the numbers of a single-device run."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = """
import json, sys
sys.path.insert(0, {tests!r})
import jax
from hier_env import make_keydoor
from smjax.train import TrainConfig
from smjax.train.run import run
# short levels and turns: what is compared is every number, not how well it learned
cfg = TrainConfig(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=160,
                  success_window=64, gate_envs=32, eval_envs=32, finetune_max_episodes=96,
                  finetune_turn_episodes=48)
r = run(make_keydoor(), cfg, {seeds!r}, progress=False)
print(json.dumps({{"devices": len(jax.devices()), "levels": r["levels"], "final": r["final_success"],
                  "finetune": r["finetune"]}}))
"""


def _run(devices: int, seeds: list[int]) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu",
               XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    code = SCRIPT.format(tests=str(Path(__file__).parent), seeds=seeds)
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_seed_sharding_matches_single_device():
    # a seed on each device, against both seeds on one device
    one = _run(1, [0, 1])
    two = _run(2, [0, 1])
    assert one["devices"] == 1 and two["devices"] == 2
    assert two["levels"] == one["levels"]
    assert two["final"] == one["final"] and two["finetune"] == one["finetune"]
    assert min(one["finetune"]["episodes"]) > 0  # every seed reached its fine-tuning turns


@pytest.mark.slow  # ~80 s on 2 cores; sharded == single-device is the fast test above
def test_seeds_and_environments_sharded_together_run():
    # 2 seeds on 4 devices: each seed's 16 environments are split over 2 devices
    two = _run(4, [0, 1])
    assert len(two["final"]) == 2
    assert [lvl["template"] for lvl in two["levels"]] == ["open_door", "give_key"]
