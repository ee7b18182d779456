"""The ``smjax`` command: train, bench, list, plot, eval, render. ``smjax COMMAND --help``
explains each."""
from __future__ import annotations

import argparse
import atexit
import contextlib
import json
import os
import shlex
import signal
import sys
from pathlib import Path

from smjax.cli_errors import UsageError, user_message
from smjax.cli_policy import add_eval, add_render, check_image_path, cmd_eval, cmd_render
from smjax.cli_train import add_distributed, cmd_train, key_values

DESCRIPTION = """\
smjax: vectorized reinforcement learning with option templates (Sticky Mittens) in JAX.

Commands:
  train   train a task top-down (the paper's method), bottom-up or flat; writes
          results.json, curves.csv, curves.png and the saved policy (policy/) to --out
  bench   environment steps per second (one JSON line)
  list    the registered tasks (ENV/TASK) and, with --hierarchies, their hierarchies
  plot    overlay learning curves of several runs
  eval    evaluate a run's saved policy: task success and return per seed (one JSON line)
  render  write a GIF of an episode (random policy, or a run's saved policy with --policy)

Your own environment: a module that calls smjax.core.register("ENV/TASK", factory) when
imported; name the task MODULE:ENV/TASK, or pass --import MODULE to any command.

Examples:
  smjax train craft/get_wood --seeds 2 --out runs/wood
  smjax eval runs/wood --episodes 256 --seed 1
  smjax train craft/get_gem --method top-down --algo ppo --seeds 10 --out runs/gem
  smjax bench craft/get_gem --num-envs 4096 --steps 200
  smjax train mypkg.envs:keydoor/find_treasure --out runs/treasure

Several hosts (run the same command on each, changing --process-id):
  smjax train craft/get_gem --seeds 16 --out runs/gem --coordinator 10.0.0.1:1234 \
      --num-processes 2 --process-id 0
"""


def _add_debug(p) -> None:
    p.add_argument("--debug", action="store_true",
                   help="show the full traceback of an error instead of one line")
    p.add_argument("--import", dest="imports", action="append", metavar="MODULE", default=[],
                   help="import MODULE first: a module of yours that registers tasks with "
                        "smjax.core.register (searched in the installed packages, then the "
                        "working directory); or name the task MODULE:ENV/TASK")


def _import_user_modules(args) -> None:
    from smjax.core.registry import import_env_module

    for module in getattr(args, "imports", None) or []:
        import_env_module(module)


def _add_train(sub):
    from smjax.train.config import ALGOS, METHODS

    p = sub.add_parser("train", help="train a task", formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Train ENV/TASK. All seeds train together in one compiled program.\n"
                                   "Every TrainConfig field can be set with --set FIELD=VALUE or a "
                                   "--config YAML/JSON file; learner hyper-parameters with "
                                   "--agent KEY=VALUE.")
    p.add_argument("task", help="registered task, e.g. craft/get_gem (see `smjax list`), or "
                                "your own as MODULE:ENV/TASK, e.g. mypkg.envs:keydoor/find_treasure")
    p.add_argument("--method", choices=METHODS, default=None, help="default: top-down")
    p.add_argument("--algo", choices=ALGOS, default=None, help="learner for every level (default: ppo)")
    p.add_argument("--seeds", type=int, default=None, help="number of seeds (0..N-1, shifted by --seed-offset; default 1)")
    p.add_argument("--seed-offset", type=int, default=0)
    p.add_argument("--resume", default=None, metavar="DIR",
                   help="continue the run checkpointed in DIR (its saved config is the base; "
                        "flags that contradict it are refused)")
    p.add_argument("--resume-from", default=None, metavar="STEP",
                   help="with --resume: the checkpoint step to continue from (e.g. step-30, the "
                        "previous good one kept beside a corrupt latest)")
    p.add_argument("--out", default=None, help="output directory (default: runs/ENV_TASK_METHOD)")
    p.add_argument("--config", default=None, help="YAML or JSON file with TrainConfig fields")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE", help="override a TrainConfig field")
    p.add_argument("--agent", action="append", metavar="KEY=VALUE",
                   help="learner hyper-parameter (a field of the algo's config, e.g. "
                        "learning_rate=3e-4, hidden_sizes=[128,128], torso=conv: convolutions "
                        "over the observation's grids, recurrent_size=64: a GRU memory)")
    p.add_argument("--env", action="append", metavar="KEY=VALUE", help="environment override")
    p.add_argument("--sweep", action="append", metavar="FIELD=V1,V2",
                   help="hyper-parameter sweep, e.g. --sweep agent.learning_rate=1e-4,3e-4 "
                        "[--sweep agent.ent_coef=0,0.01]: every point of the lists' product "
                        "trains for every seed in the same one compiled program; writes "
                        "OUT/sweep.json and OUT/point-<k>/results.json (a point's results are "
                        "those of its run alone). Sweepable: gamma and the fields the "
                        "learner's config declares traced (docs/guide.md, \"Sweeps\"); "
                        "another field is refused with the list")
    p.add_argument("--hierarchy", default=None, help="hierarchy name (see `smjax list --hierarchies`)")
    p.add_argument("--num-envs", type=int, default=None, help="parallel environments per seed")
    _add_train_budgets(p)
    p.add_argument("--tensorboard", action="store_true", help="also write TensorBoard event files to OUT/tensorboard")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the run already in --out (its results, curves and checkpoints)")
    p.add_argument("--quiet", action="store_true", help="no progress bars; print only the summary line")
    p.add_argument("--profile", action="store_true",
                   help="print where the command's time went, from process start to the last file "
                        "written (imports, set-up, tracing and compiling, chunks, gates, evaluation, "
                        "checkpoints, results), and write it to OUT/profile.json")
    _add_debug(p)
    add_distributed(p)
    # what ``cmd_train`` fills in for the error messages of ``_run_command``: the output
    # directory (the resume command after an interruption), the batch (out of memory)
    p.set_defaults(run_out=None, run_batch=None)


def _add_train_budgets(p):
    """``smjax train``'s level and fine-tuning flags."""
    p.add_argument("--threshold", type=float, default=None,
                   help="success threshold per level (0, 1]; a level ends when its running success "
                        "reaches it and the frozen policy passes it on fresh episodes (--set "
                        "gate=false: running success alone)")
    p.add_argument("--max-episodes", type=int, default=None, help="episode budget per level")
    p.add_argument("--max-steps", type=int, default=None,
                   help="env-step budget per level (0: none); per-template budgets and thresholds: "
                        "--set 'levels={\"attack\": {\"max_steps_per_level\": 1500000}}'")
    p.add_argument("--finetune", choices=("on", "off", "auto"), default=None,
                   help="after the levels, fine-tune the learned hierarchy without teleports until "
                        "its task success passes --set finetune_threshold (0.92) (default auto: on "
                        "for top-down; docs/guide.md, 'Fine-tuning')")
    p.add_argument("--finetune-mode", choices=("turns", "joint"), default=None,
                   help="how fine-tuning trains the learned options: all at once from every "
                        "episode (joint, the default), or one at a time in turns")
    p.add_argument("--finetune-episodes", type=int, default=None, metavar="N",
                   help="fine-tuning's episode budget per seed (default 20000)")
    p.add_argument("--fixed-map", action="store_true", help="Craft: one fixed map per run (the paper's setting)")


def _add_bench(sub):
    p = sub.add_parser("bench", help="environment steps per second (JSON line)")
    p.add_argument("task")
    p.add_argument("--num-envs", type=int, default=1024)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--env", action="append", metavar="KEY=VALUE", help="environment override, e.g. observation=none")
    _add_debug(p)


def _cmd_bench(args) -> int:
    from smjax.bench import bench
    from smjax.core.files import json_safe

    # libraries print import notes (MuJoCo's "Failed to import warp") on stdout, which
    # must hold only the JSON line (``smjax bench ... | jq``)
    with contextlib.redirect_stdout(sys.stderr):
        result = bench(args.task, args.num_envs, args.steps, args.repeats,
                       **key_values(args.env, "--env"))
    print(json.dumps(json_safe(result), allow_nan=False))
    return 0


def _add_list(sub):
    p = sub.add_parser("list", help="registered tasks")
    p.add_argument("--hierarchies", action="store_true", help="also show each task's hierarchies")
    p.add_argument("prefix", nargs="?", default="", help="only tasks starting with this")
    _add_debug(p)


def _cmd_list(args) -> int:
    # from the module, not the package: a folder named smjax beside a user's script can
    # shadow the package's __init__ while its modules still import
    from smjax.core.registry import make, registry, unavailable

    missing = {env: why for env, why in unavailable().items() if env.startswith(args.prefix)
               or args.prefix.startswith(env + "/")}
    if not missing and not any(name.startswith(args.prefix) for name in registry()):
        raise UsageError(f"no registered task starts with {args.prefix!r}; `smjax list` shows "
                         f"them all")
    for name, desc in registry().items():
        if not name.startswith(args.prefix):
            continue
        print(f"{name:28s} {desc}")
        if args.hierarchies:
            env, _ = make(name)
            for hname, h in env.hierarchies().items():
                print(f"    [{hname}]")
                for line in h.describe().splitlines():
                    print(f"      {line}")
    for env, why in missing.items():  # its tasks are not registered: say what to install
        print(f"{env + '/...':28s} not available: {why}")
    return 0


def _add_plot(sub):
    p = sub.add_parser("plot", help="overlay learning curves of runs")
    p.add_argument("runs", nargs="+", help="run directories (each with curves.csv)")
    p.add_argument("--out", default="curves.png", help="image file (.png unless another "
                                                        "suffix, e.g. .pdf or .svg, is given)")
    p.add_argument("--title", default=None)
    _add_debug(p)


def _cmd_plot(args) -> int:
    from smjax.viz.plots import check_curves, plot_curves

    check_image_path(args.out)
    for d in args.runs:
        check_curves(Path(d))
    print(plot_curves(args.runs, args.out, title=args.title))
    return 0


MAX_MESSAGE = 2_000  # characters of an error line (a task list is the longest meant)


def _run_command(command, args) -> int:
    """Run a command; a user's mistake is one line on stderr and exit code 2."""
    try:
        _import_user_modules(args)
        return command(args)
    except KeyboardInterrupt:
        out = getattr(args, "run_out", None)
        how = (f"; resume with: smjax train {args.task} --resume {shlex.quote(str(out))}"
               if out is not None and (Path(out) / "checkpoints").is_dir() else "")
        print(f"interrupted{how}", file=sys.stderr)
        return 130
    except Exception as err:  # noqa: BLE001 - every error is reported, in one line
        if getattr(args, "debug", False):
            raise
        from smjax.train.bounds import short_message

        message = user_message(err, getattr(args, "run_batch", None))
        if message is not None:
            # a message that repeats a huge value (a 200 kB field) stays readable
            print(f"error: {short_message(message, MAX_MESSAGE)}", file=sys.stderr)
            return 2
        print(f"error: internal error {type(err).__name__}: {str(err).strip()[:300]} (rerun "
              f"with --debug for the traceback and report it)", file=sys.stderr)
        return 1


class _Parser(argparse.ArgumentParser):
    """argparse with a short error: the mistake and where help is, not the whole usage
    (16 lines for ``train``, which hide the one that matters). Subcommands inherit it."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n(see `{self.prog} --help`)\n")


def main(argv=None) -> int:
    parser = _Parser(prog="smjax", description=DESCRIPTION,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_train(sub)
    _add_bench(sub)
    _add_list(sub)
    _add_plot(sub)
    add_eval(sub, _add_debug)
    add_render(sub, _add_debug)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    if args.command in ("train", "eval", "render"):  # bench reports compile time: it compiles afresh
        from smjax.core.compile_cache import enable_compilation_cache

        enable_compilation_cache()
    command = {"train": cmd_train, "bench": _cmd_bench, "list": _cmd_list, "plot": _cmd_plot,
               "eval": cmd_eval, "render": cmd_render}[args.command]
    # schedulers (SLURM, ...) send SIGTERM before they kill a job: end as on Ctrl-C, lock
    # released and the resume command printed, instead of dying on the spot
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        return _run_command(command, args)
    finally:
        signal.signal(signal.SIGTERM, previous)


def entry(argv=None) -> int:
    """The ``smjax`` command: ``main``, then an exit without the interpreter's teardown.

    Tearing the interpreter down after a run frees every compiled program and array one
    by one (half a second on a CPU) and waits for a compile ahead of an interrupted or
    failed run (``smjax.train.ahead``) to finish; neither writes anything the user keeps.
    So the command ends with ``os._exit`` once the exit handlers (logging, TensorBoard's
    writer, JAX's own) have run and the streams are flushed. Called from Python with
    ``argv`` (a test, a notebook), it returns instead, unless a compile is still running."""
    code = main(argv)
    ahead = sys.modules.get("smjax.train.ahead")  # not imported: nothing compiled ahead
    if ahead is not None and ahead.compiling():
        # the exit handlers would wait on that compile too
        _exit_now(code, run_handlers=False)
    if argv is None:
        _exit_now(code, run_handlers=True)
    return code


def _exit_now(code: int, run_handlers: bool) -> None:
    if run_handlers:
        atexit._run_exitfuncs()  # what a normal exit runs before its teardown
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _terminate(signum, frame):
    raise KeyboardInterrupt


if __name__ == "__main__":
    sys.exit(entry())
