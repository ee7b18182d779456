"""Where a run's chunks go: each chunk's seconds against how many seeds were training in it
and how many of those were fine-tuning.

    JAX_PLATFORMS=cpu taskset -c 0,1 python benchmarks/chunk_timeline.py craft/get_gold \
        --seeds 10 --env observation=compact --out runs/bench/gold10_timeline.jsonl

Trains the task as ``smjax train`` would with its defaults (no output directory), writes one
record per chunk to ``--out`` (its seconds and where each training seed stood after it: "L1",
"L2", ..., "FT") and prints the chunks grouped by (seeds training, of them fine-tuning): a
chunk with one seed left is that seed's alone, and on a CPU with seed groups on threads
shows what a core left idle costs. ``--summary FILE`` prints the grouping of a written file.
"""
from __future__ import annotations

import argparse
import collections
import json


def summary(path: str) -> None:
    rows = [json.loads(line) for line in open(path)]
    groups = collections.defaultdict(lambda: [0, 0.0])
    for r in rows:
        key = (len(r["where"]), sum(w == "FT" for w in r["where"]))
        groups[key][0] += 1
        groups[key][1] += r["s"]
    print(f"{path}: {len(rows)} chunks, {sum(r['s'] for r in rows):.1f} s")
    for (seeds, tuning), (count, seconds) in sorted(groups.items()):
        print(f"  {seeds:3d} seeds training ({tuning} fine-tuning): {count:4d} chunks "
              f"{seconds:7.1f} s, {seconds / count:.3f} s a chunk")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("task", nargs="?")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--seed-offset", type=int, default=0, help="the first seed")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a training config field, as smjax train --set")
    ap.add_argument("--out", help="the per-chunk records (jsonl)")
    ap.add_argument("--summary", help="print the grouping of this file and stop")
    args = ap.parse_args()
    if args.summary:
        summary(args.summary)
        return
    if not (args.task and args.out):
        ap.error("a task and --out (or --summary FILE)")

    from smjax.cli_train import key_values
    from smjax.train.config import resolve_config
    from smjax.train.hooks import Hook
    from smjax.train.run import run

    class Timeline(Hook):
        def __init__(self, file):
            self.file = file

        def chunk(self, trainer, report):
            self.file.write(json.dumps({"chunk": report.chunk, "s": report.seconds,
                                        "where": [x.where for x in report.seeds]}) + "\n")

    env = dict(kv.split("=", 1) for kv in args.env)
    with open(args.out, "w") as file:
        cfg = resolve_config(sets=key_values(args.set, "--set"))
        seeds = list(range(args.seed_offset, args.seed_offset + args.seeds))
        run(args.task, cfg, seeds, None, env_overrides=env, progress=False,
            hooks=[Timeline(file)])
    summary(args.out)


if __name__ == "__main__":
    main()
