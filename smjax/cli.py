"""The ``smjax`` command: train, bench, list, plot, render. ``smjax COMMAND --help`` explains each."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

DESCRIPTION = """\
smjax: vectorized reinforcement learning with option templates (Sticky Mittens) in JAX.

Commands:
  train   train a task top-down (the paper's method), bottom-up or flat; writes
          results.json, curves.csv and curves.png to --out
  bench   environment steps per second (one JSON line)
  list    the registered tasks (ENV/TASK) and, with --hierarchies, their hierarchies
  plot    overlay learning curves of several runs
  render  write a GIF of an episode (random policy, or a trained hierarchy with --policy)

Examples:
  smjax train craft/get_wood --seeds 2 --out runs/wood
  smjax train craft/get_gem --method top-down --algo ppo --seeds 10 --out runs/gem
  smjax bench craft/get_gem --num-envs 4096 --steps 200

Several hosts (run the same command on each, changing --process-id):
  smjax train craft/get_gem --seeds 16 --out runs/gem --coordinator 10.0.0.1:1234 \
      --num-processes 2 --process-id 0
"""


def _parse_value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _key_values(items, what: str) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"error: {what} must look like KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = _parse_value(v)
    return out


def _add_train(sub):
    from smjax.train.config import ALGOS, METHODS

    p = sub.add_parser("train", help="train a task", formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Train ENV/TASK. All seeds train together in one compiled program.\n"
                                   "Every TrainConfig field can be set with --set FIELD=VALUE or a "
                                   "--config YAML/JSON file; learner hyper-parameters with "
                                   "--agent KEY=VALUE.")
    p.add_argument("task", help="registered task, e.g. craft/get_gem (see `smjax list`)")
    p.add_argument("--method", choices=METHODS, default=None, help="default: top-down")
    p.add_argument("--algo", choices=ALGOS, default=None, help="learner for every level (default: ppo)")
    p.add_argument("--seeds", type=int, default=None, help="number of seeds (0..N-1, shifted by --seed-offset; default 1)")
    p.add_argument("--seed-offset", type=int, default=0)
    p.add_argument("--resume", default=None, metavar="DIR",
                   help="continue the run checkpointed in DIR (its saved config is the base; "
                        "flags that contradict it are refused)")
    p.add_argument("--out", default=None, help="output directory (default: runs/ENV_TASK_METHOD)")
    p.add_argument("--config", default=None, help="YAML or JSON file with TrainConfig fields")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE", help="override a TrainConfig field")
    p.add_argument("--agent", action="append", metavar="KEY=VALUE", help="learner hyper-parameter")
    p.add_argument("--env", action="append", metavar="KEY=VALUE", help="environment override")
    p.add_argument("--hierarchy", default=None, help="hierarchy name (see `smjax list --hierarchies`)")
    p.add_argument("--num-envs", type=int, default=None, help="parallel environments per seed")
    p.add_argument("--threshold", type=float, default=None,
                   help="success threshold per level (0, 1]; a level ends when its running success "
                        "reaches it and the frozen policy passes it on fresh episodes (--set "
                        "gate=false: running success alone)")
    p.add_argument("--max-episodes", type=int, default=None, help="episode budget per level")
    p.add_argument("--max-steps", type=int, default=None,
                   help="env-step budget per level (0: none); per-template budgets and thresholds: "
                        "--set 'levels={\"attack\": {\"max_steps_per_level\": 1500000}}'")
    p.add_argument("--fixed-map", action="store_true", help="Craft: one fixed map per run (the paper's setting)")
    p.add_argument("--tensorboard", action="store_true", help="also write TensorBoard event files to OUT/tensorboard")
    p.add_argument("--quiet", action="store_true", help="no progress bars; print only the summary line")
    _add_distributed(p)


def _add_distributed(p) -> None:
    g = p.add_argument_group(
        "several processes / hosts (jax.distributed)",
        "Start the same command once per process; all of them train together. Unset values "
        "come from JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID. Only process 0 "
        "writes (results, checkpoints, plots) and prints; --out is on process 0's disk.")
    g.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                   help="address of process 0 (reachable from every process)")
    g.add_argument("--num-processes", type=int, default=None, metavar="N", help="processes in the run")
    g.add_argument("--process-id", type=int, default=None, metavar="I", help="this process, 0..N-1")
    g.add_argument("--local-device-ids", default=None, metavar="IDS",
                   help="comma-separated local device ids this process uses (e.g. one GPU each: 0 / 1)")
    g.add_argument("--cluster", nargs="?", const=True, default=False, metavar="METHOD",
                   help="let JAX detect unset values from the cluster (SLURM, Open MPI, ...); "
                        "optionally name the method, e.g. mpi4py")


def _initialize_distributed(args) -> None:
    """Join the multi-process run the flags / environment describe (nothing for one process)."""
    from smjax.train.distributed import initialize

    ids = None
    if args.local_device_ids:
        try:
            ids = [int(x) for x in args.local_device_ids.split(",")]
        except ValueError:
            raise ValueError(f"--local-device-ids must be comma-separated integers, "
                             f"got {args.local_device_ids!r}") from None
    initialize(args.coordinator, args.num_processes, args.process_id, local_device_ids=ids,
               auto_detect=args.cluster)


def _cmd_train(args) -> int:
    from smjax.train.config import ConfigError, TrainConfig
    from smjax.train.run import run

    from smjax.train import checkpoint as ckpt
    from smjax.train.distributed import is_writer

    try:  # before anything touches JAX
        _initialize_distributed(args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    saved = None
    if args.resume:
        info = ckpt.shared_meta(args.resume)
        if info is None:
            print(f"error: nothing to resume: no checkpoint in {args.resume}", file=sys.stderr)
            return 2
        saved = info["meta"]["run"]
        if saved["task"] != args.task:
            print(f"error: {args.resume} is a run of {saved['task']!r}, not {args.task!r}", file=sys.stderr)
            return 2
    names = set(TrainConfig.__dataclass_fields__)
    data = {k: v for k, v in saved.items() if k in names} if saved else {}
    if args.config:
        data.update(TrainConfig.from_file(args.config).to_dict())
    data.update(_key_values(args.set, "--set"))
    for field, value in (("method", args.method), ("algo", args.algo), ("hierarchy", args.hierarchy),
                         ("num_envs", args.num_envs), ("threshold", args.threshold),
                         ("max_episodes_per_level", args.max_episodes),
                         ("max_steps_per_level", args.max_steps)):
        if value is not None:
            data[field] = value
    if args.tensorboard:
        data["tensorboard"] = True
    if args.agent:
        data["agent"] = dict(data.get("agent", {})) | _key_values(args.agent, "--agent")
    try:
        cfg = TrainConfig.from_dict(data)
    except (ConfigError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    env_over = dict(saved["env_overrides"]) if saved else {}
    env_over.update(_key_values(args.env, "--env"))
    if args.fixed_map:
        env_over["fixed_map"] = True
    if args.seeds is not None and args.seeds < 1:
        print("error: --seeds must be >= 1", file=sys.stderr)
        return 2
    if args.seeds is None and saved:
        seeds = list(saved["seeds"])
    else:
        seeds = list(range(args.seed_offset, args.seed_offset + (args.seeds or 1)))
    out = args.resume or args.out or f"runs/{args.task.replace('/', '_')}_{cfg.method}"
    try:
        results = run(args.task, cfg, seeds, out, env_overrides=env_over, progress=not args.quiet,
                      resume=bool(args.resume))
    except (KeyError, ValueError, TypeError, FileExistsError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if not is_writer():  # process 0 reports for the whole run
        return 0
    summary = {k: results[k] for k in ("env", "task", "method", "algo", "episodes_to_threshold",
                                       "final_success", "wall_seconds", "compile_seconds")}
    print(json.dumps(summary))
    print(f"wrote {Path(out) / 'results.json'}, curves.csv, curves.png")
    return 0


def _add_bench(sub):
    p = sub.add_parser("bench", help="environment steps per second (JSON line)")
    p.add_argument("task")
    p.add_argument("--num-envs", type=int, default=1024)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--env", action="append", metavar="KEY=VALUE", help="environment override, e.g. observation=none")


def _cmd_bench(args) -> int:
    from smjax.bench import bench

    try:
        print(json.dumps(bench(args.task, args.num_envs, args.steps, args.repeats,
                               **_key_values(args.env, "--env"))))
    except (KeyError, ValueError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


def _add_list(sub):
    p = sub.add_parser("list", help="registered tasks")
    p.add_argument("--hierarchies", action="store_true", help="also show each task's hierarchies")
    p.add_argument("prefix", nargs="?", default="", help="only tasks starting with this")


def _cmd_list(args) -> int:
    import smjax

    for name, desc in smjax.registry().items():
        if not name.startswith(args.prefix):
            continue
        print(f"{name:28s} {desc}")
        if args.hierarchies:
            env, _ = smjax.make(name)
            for hname, h in env.hierarchies().items():
                print(f"    [{hname}]")
                for line in h.describe().splitlines():
                    print(f"      {line}")
    return 0


def _add_plot(sub):
    p = sub.add_parser("plot", help="overlay learning curves of runs")
    p.add_argument("runs", nargs="+", help="run directories (each with curves.csv)")
    p.add_argument("--out", default="curves.png")
    p.add_argument("--title", default=None)


def _cmd_plot(args) -> int:
    from smjax.viz.plots import plot_curves

    for d in args.runs:
        if not (Path(d) / "curves.csv").exists():
            print(f"error: {d} has no curves.csv", file=sys.stderr)
            return 2
    print(plot_curves(args.runs, args.out, title=args.title))
    return 0


def _add_render(sub):
    p = sub.add_parser("render", help="write a GIF of an episode")
    p.add_argument("task")
    p.add_argument("--policy", default=None, metavar="DIR",
                   help="a run directory: play its trained hierarchy (no teleports); default: random actions")
    p.add_argument("--out", default="episode.gif")
    p.add_argument("--steps", type=int, default=200, help="most steps to render")
    p.add_argument("--seed-index", type=int, default=0, help="which of the run's seeds to play")
    p.add_argument("--fps", type=float, default=8)
    p.add_argument("--env", action="append", metavar="KEY=VALUE", help="environment override (random play)")


def _cmd_render(args) -> int:
    from smjax.train.policy import frames_of, play_random, play_trained
    from smjax.viz.gif import write_gif

    try:
        if args.policy:
            env, params, states, total = play_trained(args.policy, seed_index=args.seed_index,
                                                      max_ticks=args.steps)
            if env.name != args.task:
                print(f"error: {args.policy} is a run of {env.name!r}, not {args.task!r}", file=sys.stderr)
                return 2
            note = f"return {total:.2f}"
        else:
            env, params, states = play_random(args.task, steps=args.steps,
                                              env_overrides=_key_values(args.env, "--env"))
            note = "random actions"
        write_gif(frames_of(env, params, states), args.out, fps=args.fps)
    except (KeyError, ValueError, TypeError, FileNotFoundError, RuntimeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.out} ({len(states)} frames, {note})")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="smjax", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_train(sub)
    _add_bench(sub)
    _add_list(sub)
    _add_plot(sub)
    _add_render(sub)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    if args.command in ("train", "render"):  # bench reports compile time: it compiles afresh
        from smjax.core.compile_cache import enable_compilation_cache

        enable_compilation_cache()
    return {"train": _cmd_train, "bench": _cmd_bench, "list": _cmd_list, "plot": _cmd_plot,
            "render": _cmd_render}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
