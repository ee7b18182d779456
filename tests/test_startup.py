"""Start-up: a run imports only what it uses (plotting, TensorBoard and MuJoCo cost
seconds of import before anything trains), and the timeline that ``--profile`` prints."""
import json
import os
import subprocess
import sys
from pathlib import Path

from smjax.core.timeline import Timeline

ROOT = Path(__file__).resolve().parents[1]

_CRAFT_RUN = """
import json, sys
from smjax.train import TrainConfig
from smjax.train.run import run
cfg = TrainConfig(num_envs=8, rollout_ticks=4, max_episodes_per_level=8, success_window=4,
                  gate=False, eval_envs=8, eval_max_ticks=20, finetune="off")
run("craft/get_wood", cfg, [0], progress=False)
heavy = ("matplotlib", "tensorboardX", "mujoco", "brax", "tqdm", "PIL")
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in heavy)))
"""


def test_a_craft_run_imports_no_plotting_tensorboard_or_mujoco():
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", _CRAFT_RUN], env=env, capture_output=True,
                         text=True, check=True, timeout=600)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_the_timeline_sums_repeated_spans_and_orders_them_by_start():
    t = Timeline(start=0.0)
    t.add("b", 5.0, 1.0)
    t.add("a", 1.0, 2.0)
    t.add("b", 9.0, 0.5)
    d = t.to_dict()
    assert [s["label"] for s in d["spans"]] == ["a", "b"]
    assert d["spans"][1] == {"label": "b", "start": 5.0, "seconds": 1.5, "count": 2}
    with t.span("c"):
        pass
    assert t.spans["c"][2] == 1 and t.spans["c"][1] >= 0
    assert "a" in t.report() and "whole command" in t.report()


def test_the_timeline_starts_at_the_process_start():
    # the interpreter ran before this module was imported: the clock started earlier
    assert Timeline().now() > 0.0
