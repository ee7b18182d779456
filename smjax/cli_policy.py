"""``smjax eval`` and ``smjax render``: a run's saved policy (``RUN/policy``) evaluated or
played without a trainer (``smjax.load_policy``), and random play for a first look."""
from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

from smjax.cli_errors import UsageError
from smjax.cli_train import key_values

MAX_RENDER_STEPS = 100_000
MAX_EVAL_EPISODES = 1_000_000


def check_image_path(out: str) -> None:
    """Refuse an output path that cannot take an image file, before any work."""
    from smjax.cli_train import short_text
    from smjax.train.outdir import check_path_names

    check_path_names("--out", out)
    path = Path(out)
    try:
        is_dir, has_folder = path.is_dir(), path.parent.is_dir()
    except OSError as err:  # e.g. a path longer than the system allows
        raise UsageError(f"--out {short_text(out)}: {err.strerror or err}") from None
    if not out.strip() or is_dir:
        raise UsageError(f"--out {short_text(out)} is a directory or empty; name an image file")
    if not has_folder:
        raise UsageError(f"--out {short_text(out)}: folder {short_text(str(path.parent))} does "
                         f"not exist")


def add_eval(sub, add_debug) -> None:
    p = sub.add_parser("eval", help="evaluate a run's saved policy (one JSON line)",
                       description="Evaluate the hierarchy a run saved in DIR/policy, alone (no "
                                   "teleports, nobody learning): the task success and return of "
                                   "every seed's hierarchy over fresh episodes. With the defaults "
                                   "it repeats the run's own final evaluation (final_success).")
    p.add_argument("run", metavar="DIR", help="a run directory (smjax train --out DIR)")
    p.add_argument("--episodes", type=int, default=None,
                   help="episodes per seed (default: the run's eval_envs)")
    p.add_argument("--seed", type=int, default=None,
                   help="key of the episodes (default: the run's final evaluation's)")
    p.add_argument("--max-ticks", type=int, default=None,
                   help="steps after which an unfinished episode fails (default: the run's "
                        "eval_max_ticks)")
    add_debug(p)


def cmd_eval(args) -> int:
    from smjax.core.files import json_safe
    from smjax.policy import load_policy

    if args.episodes is not None and not 1 <= args.episodes <= MAX_EVAL_EPISODES:
        raise UsageError(f"--episodes must be in [1, {MAX_EVAL_EPISODES}], got {args.episodes}")
    if args.seed is not None and not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.max_ticks is not None and args.max_ticks < 1:
        raise UsageError(f"--max-ticks must be >= 1, got {args.max_ticks}")
    # (library notes on stdout would spoil the JSON line: ``smjax eval DIR | jq``)
    with contextlib.redirect_stdout(sys.stderr):
        policy = load_policy(args.run)
        result = policy.evaluate(args.episodes, args.seed, args.max_ticks)
    mean = {f"mean_{k}": sum(result[k]) / len(result[k]) for k in ("success", "return")}
    print(json.dumps(json_safe(result | mean), allow_nan=False))
    return 0


def add_render(sub, add_debug) -> None:
    p = sub.add_parser("render", help="write a GIF of an episode",
                       description="Write a GIF of one episode of ENV/TASK: random actions, or "
                                   "with --policy the hierarchy a run saved, executing its own "
                                   "learned options (no teleports).")
    p.add_argument("task", help="the task, as trained (e.g. craft/get_gem)")
    p.add_argument("--policy", default=None, metavar="DIR",
                   help="a run directory: play its saved policy (no teleports); default: random actions")
    p.add_argument("--out", default="episode.gif", help="the GIF to write (default episode.gif)")
    p.add_argument("--steps", type=int, default=200,
                   help="most environment steps to render (default 200; the episode may end sooner)")
    p.add_argument("--seed-index", type=int, default=0, help="which of the run's seeds to play")
    p.add_argument("--seed", type=int, default=0, help="key of the episode (default 0)")
    p.add_argument("--fps", type=float, default=8, help="frames per second of the GIF (default 8)")
    p.add_argument("--env", action="append", metavar="KEY=VALUE", help="environment override (random play)")
    add_debug(p)


def cmd_render(args) -> int:
    from smjax.viz.gif import write_gif
    from smjax.viz.play import random_frames

    if not 1 <= args.steps <= MAX_RENDER_STEPS:  # each step's frame is kept in memory
        raise UsageError(f"--steps must be in [1, {MAX_RENDER_STEPS}], got {args.steps}")
    if not 0.1 <= args.fps <= 1000:  # (a GIF stores a frame's duration in 1/100 s)
        raise UsageError(f"--fps must be in [0.1, 1000], got {args.fps:g}")
    if not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed must be in [0, 2**32), got {args.seed}")
    check_image_path(args.out)  # before playing, which may take minutes
    if args.policy:
        from smjax.policy import load_policy

        if args.env:
            raise UsageError("--env is for random play; a saved policy plays in the "
                             "environment it was trained in")
        policy = load_policy(args.policy, task=args.task)
        frames, ret = policy.render(args.seed_index, max_steps=args.steps, seed=args.seed)
        note = f"return {ret:.2f}"
    else:
        frames = random_frames(args.task, steps=args.steps, seed=args.seed,
                               env_overrides=key_values(args.env, "--env"))
        note = "random actions"
    write_gif(frames, args.out, fps=args.fps)
    print(f"wrote {args.out} ({len(frames)} frames, {note})")
    return 0
