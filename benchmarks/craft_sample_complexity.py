"""Craft sample complexity: top-down vs bottom-up vs flat, side by side, with the paper's numbers.

    python benchmarks/craft_sample_complexity.py --tasks get_gem get_gold --seeds 10 \
        --methods top-down bottom-up flat --out runs/craft_sc
    python benchmarks/craft_sample_complexity.py --tasks all --methods top-down --seeds 4   # every task

Writes OUT/summary.json (every run's results.json), OUT/curves_all.csv (all curves with task
and method columns), OUT/table.md, and OUT/curves_<task>.png (average reward vs episodes per
level, methods overlaid, in the paper's style). All seeds of a run train in one program.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import smjax  # noqa: F401  (sets the XLA:CPU workaround before jax starts)
from smjax.core.registry import registry
from smjax.envs.craft.oracle import best_return
from smjax.train import TrainConfig
from smjax.train.run import run
from smjax.viz.plots import plot_curves

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _stats import mean_std, reached_summary  # noqa: E402

PAPER = {"get_gem": (12826, 2613), "get_gold": (10516, 2833), "make_axe": (11283, 2255),
         "make_stick": (5026, 2231), "make_bridge": (7974, 1853)}
PAPER_CURRICULUM = {"get_gem": "> 3e6", "get_gold": "> 2.65e6", "make_axe": "> 2.7e6",
                    "make_stick": "> 1.3e6", "make_bridge": "> 1.8e6"}



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", nargs="+", default=["get_gem", "get_gold"],
                    help="Craft tasks (get_gem ...), or 'all' for every registered Craft task")
    ap.add_argument("--methods", nargs="+", default=["top-down", "bottom-up", "flat"])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--algo", default="ppo")
    ap.add_argument("--observation", default="compact", choices=["paper", "compact"])
    ap.add_argument("--num-envs", type=int, default=256)
    ap.add_argument("--max-episodes", type=int, default=40000, help="budget per level (hierarchies)")
    ap.add_argument("--flat-max-episodes", type=int, default=200000, help="budget of the flat learner")
    ap.add_argument("--fixed-map", action="store_true")
    ap.add_argument("--out", default="runs/craft_sc")
    args = ap.parse_args()
    if args.tasks == ["all"]:
        args.tasks = [name.split("/", 1)[1] for name in registry() if name.startswith("craft/")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary, rows = [], ["task,method,seed,level,template,episodes,env_steps,running_success"]
    table = ["| task | method | episodes to 0.8 (mean +- std, reached) | env steps | final_success (no teleports) "
             "| lowest seed | task's best (ceiling) "
             "| before fine-tuning | total episodes (with fine-tuning) | wall s | compile s "
             "| paper (option templates) | paper (curriculum) |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for task in args.tasks:
        run_dirs = []
        for method in args.methods:
            budget = args.flat_max_episodes if method == "flat" else args.max_episodes
            cfg = TrainConfig(method=method, algo=args.algo, num_envs=args.num_envs,
                              max_episodes_per_level=budget)
            env_over = {"observation": args.observation} | ({"fixed_map": True} if args.fixed_map else {})
            run_dir = out / f"{task}_{method}"
            res = run(f"craft/{task}", cfg, list(range(args.seeds)), run_dir, env_overrides=env_over,
                      progress=False)
            res.pop("_raw")
            summary.append(res)
            run_dirs.append(run_dir)
            for line in (run_dir / "curves.csv").read_text().splitlines()[1:]:
                rows.append(f"{task},{method},{line}")
            fs, ft = res["final_success"], res.get("finetune")
            before = "{:.2f} +- {:.2f}".format(*mean_std(ft["final_success_before"])) if ft else "-"
            paper = PAPER.get(task)
            table.append(
                f"| {task} | {method} | {reached_summary(res['episodes_to_threshold'])} | {reached_summary(res['env_steps_to_threshold'])} "
                f"| {'{:.3f} +- {:.3f}'.format(*mean_std(fs))} | {min(fs):.3f} | {best_return(task):g} | {before} "
                f"| {'{:,.0f} +- {:,.0f}'.format(*mean_std(res['total_episodes']))} | {res['wall_seconds']:.0f} "
                f"| {res['compile_seconds']:.0f} | {f'{paper[0]:,} +- {paper[1]:,}' if paper else '-'} "
                f"| {PAPER_CURRICULUM.get(task, '-')} |")
            print(table[-1], flush=True)
        plot_curves(run_dirs, out / f"curves_{task}.png", title=f"craft/{task}: average reward vs episodes")
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "curves_all.csv").write_text("\n".join(rows) + "\n")
    (out / "table.md").write_text("\n".join(table) + "\n")
    print("\n".join(table))
    print(json.dumps({"tasks": args.tasks, "methods": args.methods, "seeds": args.seeds,
                      "wall_seconds": sum(r["wall_seconds"] for r in summary)}))


if __name__ == "__main__":
    main()
