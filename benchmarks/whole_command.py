"""The whole command a user types, timed from spawn to exit, with an empty or a warm cache.

    python benchmarks/whole_command.py --label new --tree . --cache /tmp/cache_new \
        --runs cold warm --out runs/bench/new.json -- \
        train craft/make_stick --seeds 2 --env observation=compact --quiet

Runs ``python -m smjax ARGS --out DIR`` with the smjax package of ``--tree`` (so an older
checkout can be timed beside the current one in one run), ``--cache`` as the
compilation cache (emptied before a ``cold`` run, kept for a ``warm`` one), and appends one
record per run to ``--out``: wall seconds, the run's own ``wall_seconds`` and
``compile_seconds``, its final success, and where it wrote one, its profile.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def one_run(tree: Path, cache: Path, args: list[str], kind: str) -> dict:
    if kind == "cold":
        shutil.rmtree(cache, ignore_errors=True)
    out = Path(tempfile.mkdtemp(prefix="whole-command-")) / "run"
    # the tree first, then whatever the caller's path adds (e.g. wheels installed apart)
    path = os.pathsep.join(p for p in (str(tree.resolve()), os.environ.get("PYTHONPATH")) if p)
    env = dict(os.environ, PYTHONPATH=path, SMJAX_CACHE_DIR=str(cache))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    t0 = time.perf_counter()
    # run from the tree: ``python -m`` puts the working directory first on the path
    proc = subprocess.run([sys.executable, "-m", "smjax", *args, "--out", str(out)], env=env,
                          cwd=tree.resolve(), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    record = {"kind": kind, "whole_command_seconds": wall, "returncode": proc.returncode}
    if proc.returncode != 0:
        return record | {"stderr": proc.stderr[-2000:]}
    results = json.loads((out / "results.json").read_text())
    record |= {k: results[k] for k in ("wall_seconds", "compile_seconds", "final_success",
                                       "episodes_to_threshold", "total_episodes")
               if k in results}
    if results.get("finetune"):
        record["finetune_episodes"] = results["finetune"]["episodes"]
    if (out / "profile.json").is_file():
        record["profile"] = json.loads((out / "profile.json").read_text())
    shutil.rmtree(out.parent, ignore_errors=True)
    return record


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--label", required=True, help="what is timed (e.g. old, new)")
    ap.add_argument("--tree", type=Path, default=Path("."), help="folder holding smjax/")
    ap.add_argument("--cache", type=Path, required=True, help="compilation cache folder")
    ap.add_argument("--runs", nargs="+", default=["cold", "warm"], choices=["cold", "warm"])
    ap.add_argument("--out", type=Path, required=True, help="JSON lines file to append to")
    ap.add_argument("args", nargs=argparse.REMAINDER, help="-- then smjax's arguments")
    a = ap.parse_args()
    args = a.args[1:] if a.args[:1] == ["--"] else a.args
    a.out.parent.mkdir(parents=True, exist_ok=True)
    for kind in a.runs:
        record = {"label": a.label, "args": args} | one_run(a.tree, a.cache, args, kind)
        with open(a.out, "a") as f:
            f.write(json.dumps(record) + "\n")
        print(f"{a.label} {kind}: {record['whole_command_seconds']:.1f} s "
              f"(compile {record.get('compile_seconds', float('nan')):.1f} s)", flush=True)


if __name__ == "__main__":
    main()
