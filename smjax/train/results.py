"""results.json and curves.csv, in the format docs/guide.md ("Results format") describes,
written with the saved policy by ``ResultsHook``.

curves.png is drawn above this layer (``smjax.viz.plots.PlotHook``, which reads these
files): training never imports plotting."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import jax

from smjax.core.files import atomic_write_text, json_safe
from smjax.core.version import smjax_version
from smjax.policy.artifact import write_policy
from smjax.train import distributed as dist
from smjax.train.hooks import Hook, ResultsReport

# running_success: the mean success over the last success_window learner episodes (the
# level's learner; in fine-tuning, whole-task episodes). The curves.csv of an smjax that
# names it "avg_return" is read as well: ``read_curves`` renames it.
CURVE_COLUMNS = ("seed", "level", "template", "episodes", "env_steps", "running_success")
COLUMN_ALIASES = {"avg_return": "running_success"}


class ResultsError(RuntimeError):
    """Training finished (and is checkpointed) but its results could not be written; the
    message says how to write them from the checkpoint."""


def build_results(env_name: str, method: str, algo: str, seeds: list[int], threshold: float,
                  raw: dict, config: dict, success_unbounded: bool = False) -> dict:
    """results.json's content. ``success_unbounded``: the task's success is a raw return,
    so no root level or fine-tuning ended at a threshold."""
    env, task = env_name.split("/", 1)
    levels = raw["levels"]
    per_seed_eps, per_seed_steps = [], []
    for s in range(len(seeds)):
        ok = all(rec["reached"][s] for rec in levels)
        per_seed_eps.append(sum(rec["episodes"][s] for rec in levels) if ok else None)
        per_seed_steps.append(sum(rec["env_steps"][s] for rec in levels) if ok else None)
    final = raw["final"]
    by_policy = raw.get("final_by_policy") or {}
    return json_safe({
        "env": env,
        "task": task,
        "method": method,
        "algo": algo,
        "seeds": list(seeds),
        "threshold": threshold,
        "success_unbounded": bool(success_unbounded),
        "episodes_to_threshold": per_seed_eps,
        "env_steps_to_threshold": per_seed_steps,
        "final_success": [float(x) for x in final["success"]],
        "final_return": [float(x) for x in final["return"]],
        # how frozen policies picked in the evaluation behind final_success, and the
        # success under every mode
        "eval_policy": raw.get("eval_policy"),
        "final_success_by_policy": {p: [float(x) for x in r["success"]]
                                    for p, r in by_policy.items()},
        "levels": [dict(r) for r in levels],
        "finetune": _finetune_summary(raw.get("finetune"), config),
        "total_episodes": _totals(levels, raw.get("finetune"), "episodes", len(seeds)),
        "total_env_steps": _totals(levels, raw.get("finetune"), "env_steps", len(seeds)),
        "wall_seconds": raw["wall_seconds"],
        "compile_seconds": raw["compile_seconds"],
        "device": jax.devices()[0].platform,
        # threads the seeds' groups ran on (smjax.train.seed_threads): the same numbers
        # with any count, a different wall time
        "seed_threads": raw.get("seed_threads", 1),
        "jax_version": jax.__version__,
        "smjax_version": smjax_version(),
        "config": config,
    })


def _finetune_summary(record: dict | None, config: dict) -> dict | None:
    """results.json's "finetune": per seed, the phase's training episodes and env steps,
    its gate env steps, whether its gate passed, why it ended (``stop``: "gate",
    "plateau" or "budget"), its mode (``mode``: "joint" or "turns"), the mean task success
    of its plateau blocks, final_success before it, its turns (joint: one); where
    no gate passed, the fine-tuned hierarchy's check (``check_success``) and which one the
    phase handed back (``kept``: "fine-tuned" or "levels", the better of the two;
    ``baseline``: the levels' bank was kept when the phase started, to compare with)."""
    if record is None:
        return None
    return {
        "threshold": config.get("finetune_threshold"),
        "mode": config.get("finetune_mode", "turns"),
        "stop": list(record["stop"]),
        "block_means": [list(b) for b in record["block_means"]],
        "episodes": list(record["episodes"]),
        "env_steps": list(record["env_steps"]),
        "gate_env_steps": list(record["gate_env_steps"]),
        "gate_attempts": list(record["gate_attempts"]),
        "gate_success": list(record["gate_success"]),
        "reached": list(record["reached"]),
        "task_running_success": list(record["task_running"]),
        "final_success_before": list(record["success_before"]),
        "check_success": list(record["check_success"]),
        "kept": list(record["kept"]),
        "baseline": list(record["baseline"]),
        "turns": [list(t) for t in record["turns"]],
    }


def _totals(levels: list, finetune: dict | None, key: str, num_seeds: int) -> list:
    """Per seed, the training episodes (or env steps) of every level and fine-tuning."""
    out = []
    for s in range(num_seeds):
        total = sum(rec[key][s] or 0 for rec in levels)
        out.append(total + (finetune[key][s] if finetune is not None else 0))
    return out


def write_results(out_dir: str | Path, results: dict, curves: list[tuple]) -> None:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "results.json", json.dumps(results, indent=2, allow_nan=False) + "\n")
    rows = [",".join(CURVE_COLUMNS)]
    for row in curves:
        seed, level, template, eps, steps, ret = row
        ret_s = "" if ret is None or (isinstance(ret, float) and math.isnan(ret)) else f"{ret:.6g}"
        rows.append(f"{seed},{level},{template},{eps},{steps},{ret_s}")
    atomic_write_text(out / "curves.csv", "\n".join(rows) + "\n")


class ResultsHook(Hook):
    """results.json, curves.csv and the saved policy (``policy/``) in the report's
    directory: a run's, or each sweep point's. ``policy``: the saved policy's description
    of the run (``smjax.policy.artifact.policy_meta``); its seeds and config are the
    results'. Every process runs it (the policy's arrays are gathered, a collective where
    they are spread over processes); process 0 writes."""

    def __init__(self, policy: dict):
        self.policy = policy

    def results(self, trainer, report: ResultsReport) -> None:
        if report.out_dir is None:
            return
        raw, results = report.raw, report.results
        arrays = dist.gather({k: raw[k] for k in ("bank", "learned", "eval_keys")})
        if dist.is_writer():
            write_results(report.out_dir, results, raw["curves"])
            meta = self.policy | {"seeds": results["seeds"], "config": results["config"]}
            write_policy(report.out_dir, meta, arrays)


def write_sweep(out_dir: str | Path, sweep: dict) -> None:
    """sweep.json: every point's overrides and results (without the raw arrays)."""
    points = [{"overrides": p["overrides"],
               "results": {k: v for k, v in p["results"].items() if k != "_raw"}}
              for p in sweep["points"]]
    text = json.dumps(json_safe({"points": points, "compile_seconds": sweep["compile_seconds"]}),
                      indent=2, allow_nan=False)
    atomic_write_text(Path(out_dir) / "sweep.json", text + "\n")


def read_curves(path: str | Path) -> list[dict]:
    """curves.csv rows as dicts (a column under an alias renamed: ``COLUMN_ALIASES``)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [{COLUMN_ALIASES.get(k, k): v for k, v in row.items()} for row in rows]
