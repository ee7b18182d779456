"""``smjax train``: flags -> (task, config, seeds, out) -> ``smjax.train.run.run``.

Every check that can fail on a user's input runs here or in ``run`` before anything
compiles; ``smjax.cli.main`` turns the errors into one line and exit code 2.
"""
from __future__ import annotations

import errno
import json
import re
import socket
import sys
import time
from pathlib import Path

from smjax.cli_errors import UsageError
from smjax.core.timeline import TIMELINE


def short_text(text: str, limit: int = 80) -> str:
    """``repr(text)`` cut to ``limit`` characters (an error never echoes a huge value)."""
    shown = repr(text)
    return shown if len(shown) <= limit else f"{shown[:limit]}... ({len(shown)} characters)"


def parse_value(text: str):
    """``--set/--agent/--env`` values: JSON where it parses (numbers, lists, true), else text
    (each field's parser then reads words such as ``no`` strictly)."""
    from smjax.train.bounds import strict_json

    try:
        return strict_json(text)
    except json.JSONDecodeError:
        return text
    except ValueError as err:  # a key given twice
        raise UsageError(f"{short_text(text)}: {err}") from None


def key_values(items, what: str) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise UsageError(f"{what} must look like KEY=VALUE, got {short_text(item)}")
        k, v = item.split("=", 1)
        if not k.strip():
            raise UsageError(f"{what} needs a name before '=', got {short_text(item)}")
        if k != k.strip():  # a stray space is a typo, not a field name
            raise UsageError(f"{what} {short_text(item)}: the name has spaces around it")
        out[k.strip()] = parse_value(v)
    return out


def add_distributed(p) -> None:
    g = p.add_argument_group(
        "several processes / hosts (jax.distributed)",
        "Start the same command once per process; all of them train together. Unset values "
        "come from JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID. Only process 0 "
        "writes (results, checkpoints, plots) and prints; --out is on process 0's disk.")
    g.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                   help="address of process 0 (reachable from every process)")
    g.add_argument("--coordinator-timeout", type=float, default=60.0, metavar="SECONDS",
                   help="give up joining the run after this long (default 60)")
    g.add_argument("--num-processes", type=int, default=None, metavar="N", help="processes in the run")
    g.add_argument("--process-id", type=int, default=None, metavar="I", help="this process, 0..N-1")
    g.add_argument("--local-device-ids", default=None, metavar="IDS",
                   help="comma-separated local device ids this process uses (e.g. one GPU each: 0 / 1)")
    g.add_argument("--cluster", nargs="?", const=True, default=False, metavar="METHOD",
                   help="let JAX detect unset values from the cluster (SLURM, Open MPI, ...); "
                        "optionally name the method, e.g. mpi4py")


def _probe_coordinator(address: str, process_id: int | None, timeout: float) -> None:
    """Fail in bounded time, in one line, where JAX would wait silently and then abort
    with a C++ stack trace: an unresolvable host, or (for processes other than 0, which
    connect to it) a coordinator that does not answer within ``timeout`` seconds."""
    host, port = address.rsplit(":", 1)
    try:
        socket.getaddrinfo(host.strip("[]"), int(port))
    except OSError as err:
        raise UsageError(f"--coordinator {address}: host {host!r} cannot be resolved ({err}); "
                         f"check the address") from None
    if not process_id:  # process 0 hosts the coordinator: its port must be free here
        _check_port_free(address, int(port))
        return
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host.strip("[]"), int(port)), timeout=2):
                return
        except OSError:
            if time.monotonic() >= deadline:
                raise UsageError(f"--coordinator {address} did not answer within {timeout:g} s; "
                                 f"start process 0 first, check the address, or raise "
                                 f"--coordinator-timeout") from None
            time.sleep(0.5)


def _check_port_free(address: str, port: int) -> None:
    """Process 0's coordinator listens on every address at ``port``; refuse a taken port in
    one line (JAX would log a C++ error and fail to start its server)."""
    for family, host in ((socket.AF_INET6, "::"), (socket.AF_INET, "")):
        try:
            sock = socket.socket(family, socket.SOCK_STREAM)
        except OSError:  # no IPv6 on this host: try IPv4
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as gRPC binds
            sock.bind((host, port))
            return
        except OSError as err:
            if err.errno == errno.EADDRINUSE:
                raise UsageError(f"--coordinator {address}: port {port} is already in use on this "
                                 f"host, where process 0 starts the coordinator; choose a free "
                                 f"port or end the program using it") from None
        finally:
            sock.close()


MAX_COORDINATOR_TIMEOUT = 86_400  # a day: JAX takes the timeout as a whole number of seconds


def initialize_distributed(args) -> None:
    """Join the multi-process run the flags / environment describe (nothing for one process)."""
    from smjax.train.distributed import initialize, resolve

    if not 0 < args.coordinator_timeout <= MAX_COORDINATOR_TIMEOUT:  # nan and inf too
        raise UsageError(f"--coordinator-timeout must be in (0, {MAX_COORDINATOR_TIMEOUT}] "
                         f"seconds, got {args.coordinator_timeout}")
    ids = None
    if args.local_device_ids:
        try:
            ids = [int(x) for x in args.local_device_ids.split(",")]
        except ValueError:
            raise UsageError(f"--local-device-ids must be comma-separated integers, "
                             f"got {args.local_device_ids!r}") from None
    coordinator, num, pid = resolve(args.coordinator, args.num_processes, args.process_id)
    if coordinator is not None and (num or 0) > 1:
        _probe_coordinator(coordinator, pid, args.coordinator_timeout)
    initialize(args.coordinator, args.num_processes, args.process_id, local_device_ids=ids,
               auto_detect=args.cluster, initialization_timeout=max(1, int(args.coordinator_timeout)))


def _saved_run(args) -> dict | None:
    """The checkpointed run ``--resume`` names (its config is the base), checked: its
    identity and the settings it ran with (tensorboard, checkpoint_every)."""
    from smjax.train import checkpoint as ckpt

    if not args.resume:
        if args.resume_from is not None:
            raise UsageError("--resume-from STEP needs --resume DIR")
        return None
    if args.overwrite:
        raise UsageError("--resume and --overwrite contradict each other; pass one of them")
    if args.out and Path(args.out).resolve() != Path(args.resume).resolve():
        raise UsageError(f"--out {args.out} with --resume {args.resume}: a resumed run continues "
                         f"in its own directory; drop --out")
    info = ckpt.shared_meta(args.resume, args.resume_from)
    if info is None:
        raise UsageError(f"nothing to resume: no checkpoint in {args.resume} (train with --out "
                         f"{args.resume} first)")
    saved = info["meta"].get("settings", {}) | info["meta"]["run"]
    if saved.get("task") != args.task:
        raise UsageError(f"{args.resume} is a run of {saved.get('task')!r}, not {args.task!r}")
    return saved


def build_config(args, saved: dict | None):
    """The run's config from the flags (over the resumed run's, if any): ``resolve_config``."""
    from smjax.train.config import resolve_config

    sets = key_values(args.set, "--set")
    for field, value in (("method", args.method), ("algo", args.algo), ("hierarchy", args.hierarchy),
                         ("num_envs", args.num_envs), ("threshold", args.threshold),
                         ("max_episodes_per_level", args.max_episodes),
                         ("max_steps_per_level", args.max_steps), ("finetune", args.finetune),
                         ("finetune_max_episodes", args.finetune_episodes),
                         ("finetune_mode", args.finetune_mode)):
        if value is not None:
            sets[field] = value
    if args.tensorboard:
        sets["tensorboard"] = True
    return resolve_config(saved_run=saved, file=args.config, sets=sets,
                          agent=key_values(args.agent, "--agent"))


def choose_seeds(args, saved: dict | None) -> list[int]:
    if args.seeds is not None and args.seeds < 1:
        raise UsageError(f"--seeds must be >= 1, got {args.seeds}")
    if args.seed_offset < 0:
        raise UsageError(f"--seed-offset must be >= 0, got {args.seed_offset}")
    if saved and args.seeds is None and args.seed_offset == 0:
        return list(saved["seeds"])
    # with --resume, explicit seeds are compared with the checkpoint's (never ignored)
    return list(range(args.seed_offset, args.seed_offset + (args.seeds or 1)))


def cmd_train(args) -> int:
    TIMELINE.add("interpreter, imports and arguments", 0.0, TIMELINE.now())
    with TIMELINE.span("imports of training"):
        from smjax.train.distributed import is_writer
        from smjax.train.run import run
    from smjax.core.registry import get_entry
    from smjax.viz.plots import PlotHook

    for flag, value in (("--out", args.out), ("--resume", args.resume)):
        if value is not None and not value.strip():  # else the default directory is used
            raise UsageError(f"{flag} is empty (an unset shell variable?); name a directory")
    initialize_distributed(args)  # before anything touches JAX
    get_entry(args.task)  # an unknown task is refused before --out is created
    saved = _saved_run(args)
    cfg = build_config(args, saved)
    env_over = dict(saved["env_overrides"]) if saved else {}
    env_over.update(key_values(args.env, "--env"))
    if args.fixed_map:
        env_over["fixed_map"] = True
    seeds = choose_seeds(args, saved)
    sweep = choose_sweep(args, saved)
    safe_task = re.sub(r"[^\w.-]", "_", args.task)  # MODULE:ENV/TASK holds ':' and '/'
    out = args.resume or args.out or f"runs/{safe_task}_{cfg.method}"
    slots = len(seeds) * _num_points(sweep)
    args.run_batch = batch_description(cfg, slots)  # for an out-of-memory message
    args.run_out = out  # for the resume command an interruption prints
    results = run(args.task, cfg, seeds, out, env_overrides=env_over, progress=not args.quiet,
                  resume=bool(args.resume), overwrite=args.overwrite, sweep=sweep,
                  resume_from=args.resume_from, hooks=[PlotHook()])
    if not is_writer():  # process 0 reports for the whole run
        return 0
    if args.profile:
        _write_profile(out)
    if sweep is None:
        if not args.quiet:  # for a reader; stdout's JSON line is for scripts
            print(readable_summary(results, out), file=sys.stderr)
        print(json.dumps(_summary(results)))
        print(f"wrote {Path(out) / 'results.json'}, curves.csv, curves.png, policy/")
    else:
        for k, point in enumerate(results["points"]):
            if not args.quiet:
                where = Path(out) / f"point-{k}"
                print(f"point {k} {json.dumps(point['overrides'])}: "
                      f"{readable_summary(point['results'], where)}", file=sys.stderr)
            print(json.dumps({"point": k, "overrides": point["overrides"]} | _summary(point["results"])))
        print(f"wrote {Path(out) / 'sweep.json'}, point-<k>/results.json, curves.csv, curves.png, "
              f"policy/")
    sys.stdout.flush()
    return 0


def batch_description(cfg, slots: int) -> str:
    """The settings that size a run's memory, as an out-of-memory message names them: the
    batch, and the pool, window and layer sizes where they were set."""
    parts = [f"{slots} seed(s) x num_envs {cfg.run.num_envs}"]
    if cfg.run.reset_pool is not None:
        parts.append(f"reset_pool {cfg.run.reset_pool}")
    if cfg.window_slots != type(cfg).success_window:  # (the field's default)
        parts.append(f"success_window {cfg.window_slots}")
    if "hidden_sizes" in cfg.agent:
        parts.append(f"hidden_sizes {short_text(str(cfg.agent['hidden_sizes']), 40)}")
    return ", ".join(parts)


def _write_profile(out) -> None:
    """``--profile``: the timeline on stderr and in OUT/profile.json."""
    from smjax.core.files import atomic_write_text

    print(TIMELINE.report(), file=sys.stderr)
    path = Path(out) / "profile.json"
    atomic_write_text(path, json.dumps(TIMELINE.to_dict(), indent=1) + "\n")
    print(f"wrote {path}", file=sys.stderr)


def _per_seed(values, fmt: str) -> str:
    """A few seeds' values side by side; many seeds' mean and range (None: a threshold
    not reached)."""
    if len(values) <= 8:
        return "  ".join("not reached" if v is None else format(v, fmt) for v in values)
    reached = [v for v in values if v is not None]
    missing = f", {len(values) - len(reached)} not reached" if len(reached) < len(values) else ""
    if not reached:
        return "not reached"
    mean = sum(reached) / len(reached)
    mean = round(mean) if all(isinstance(v, int) for v in reached) else mean
    return (f"mean {format(mean, fmt)}, lowest {format(min(reached), fmt)}, highest "
            f"{format(max(reached), fmt)}{missing}")


def readable_summary(results: dict, out) -> str:
    """A run's outcome for a reader: per seed (or, for many seeds, their mean and range)
    the final success, the levels' episodes and fine-tuning's, and the time it took."""
    seeds = results["seeds"]
    success = results["final_success"]
    what = "final return" if results.get("success_unbounded") else "final success"
    levels = "levels' episodes"
    mean = f"mean {sum(success) / len(success):.3f}; " if 1 < len(success) <= 8 else ""
    lines = [f"{results['env']}/{results['task']}, {results['method']} {results['algo']}, "
             f"{len(seeds)} seed{'s' * (len(seeds) > 1)}:",
             f"  {what:21s}{_per_seed(success, '.3f')} ({mean}the learned hierarchy alone, "
             f"policy {results['eval_policy']})",
             f"  {levels:21s}{_per_seed(results['episodes_to_threshold'], ',')} (until each "
             f"level's threshold)"]
    tuning = results.get("finetune") or {}
    if tuning.get("episodes"):
        lines.append(f"  {'fine-tuning episodes':21s}{_per_seed(tuning['episodes'], ',')}")
    lines.append(f"  {results['wall_seconds']:.1f} s training and evaluating, "
                 f"{results['compile_seconds']:.1f} s of it compiling; files in {out}")
    return "\n".join(lines)


def _summary(results: dict) -> dict:
    return {k: results[k] for k in ("env", "task", "method", "algo", "episodes_to_threshold",
                                    "final_success", "wall_seconds", "compile_seconds")}


def choose_sweep(args, saved: dict | None) -> dict | None:
    """``--sweep`` flags, else (resuming) the checkpointed run's sweep, else None."""
    from smjax.train.sweep import parse_sweep_flags

    if args.sweep:
        return parse_sweep_flags(args.sweep)
    return saved.get("sweep") if saved else None


def _num_points(sweep: dict | None) -> int:
    count = 1
    for values in (sweep or {}).values():
        count *= max(1, len(values))
    return count
