"""Craft's ceiling: the scripted oracle (``smjax.envs.craft.oracle``) on fresh random maps.

    python benchmarks/craft_ceiling.py --episodes 1024

For each task, ``--episodes`` fresh maps (the same world generator and default step cap as
``smjax.make("craft/<task>")``; observation ``none``, which the oracle does not read) are
played by the oracle, without auto-reset, until terminated or truncated; then again with
the cap halved. Reported per (task, cap):

* ``solved``: fraction of episodes that end holding the goal;
* ``success``: the mean episode return, which is what the trainer reports as
  ``final_success`` for Craft (the reward on the terminating step, 1 less 0.1 per other item
  held then: get_gem keeps its axe, so its best is 0.9);
* ``below_best``: fraction solved with a return below the best (an obstacle grabbed);
* ``steps_*``: env steps used by the solved episodes (mean, median, 99th percentile, max);
* ``unreachable``: fraction of episodes the oracle failed because at some point no cell of
  its current target could be reached, even by grabbing or mining what was in the way
  (or none was left on the map); ``timeout``: failed for the step cap only.

Maps are the same across caps (same keys): the oracle ignores the step counter, so an
episode solved under the halved cap is exactly one solved within it under the full cap.
Writes ``benchmarks/results/craft_ceiling.json`` and prints a table.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

import smjax
from smjax.envs.craft import constants as C
from smjax.envs.craft import oracle as O

DEFAULT_TASKS = ("make_stick", "get_gem", "get_gold")


def play(task: str, num: int, seed: int, caps: tuple, chunk: int = 1024) -> list[dict]:
    """One row per cap (None: the default); one compile, the cap is a traced parameter."""
    env, params = smjax.make(f"craft/{task}", observation="none")
    goal = int(params.goal)
    best = 1.0 - 0.1 * O.solvable_items()[C.TASKS[task]][1]

    def episode(key, params):
        key_reset, key_step = jax.random.split(key)
        _, state = env.reset_env(key_reset, params)

        def cond(c):
            return ~c[1]

        def body(c):
            s, _, ret, stuck = c
            action, info = O.oracle_decide(s, goal)
            _, s, r, term, trunc, _ = env.step_env(key_step, s, action, params)
            return s, term | trunc, ret + r, stuck | info["stuck"]

        init = (state, jnp.bool_(False), jnp.float32(0.0), jnp.bool_(False))
        s, _, ret, stuck = jax.lax.while_loop(cond, body, init)
        return s.step, ret, s.inventory[goal] > 0, stuck

    keys = jax.random.split(jax.random.key(seed), num)
    chunk = min(chunk, num)
    fn = jax.jit(jax.vmap(episode, in_axes=(0, None)))
    t0 = time.perf_counter()
    compiled = fn.lower(keys[:chunk], params).compile()
    compile_s = time.perf_counter() - t0
    rows = []
    for cap in caps:
        p = params if cap is None else params.replace(max_steps=jnp.int32(cap))
        t1 = time.perf_counter()
        parts = []
        for lo in range(0, num, chunk):  # a batch runs until its slowest episode ends
            k = keys[lo:lo + chunk]
            pad = chunk - k.shape[0]
            if pad:
                k = jnp.concatenate([k, keys[:pad]])
            parts.append([np.asarray(a)[:chunk - pad] for a in compiled(k, p)])
        steps, ret, solved, stuck = (np.concatenate(c) for c in zip(*parts))
        run_s = time.perf_counter() - t1
        ok_steps = steps[solved]
        rows.append({
            "task": task,
            "cap": int(p.max_steps),
            "episodes": num,
            "solved": float(solved.mean()),
            "success": float(ret.mean()),
            "best_return": round(best, 3),
            "below_best": float((solved & (ret < best - 1e-6)).mean()),
            "steps_mean": float(ok_steps.mean()) if ok_steps.size else None,
            "steps_median": float(np.median(ok_steps)) if ok_steps.size else None,
            "steps_p99": float(np.percentile(ok_steps, 99)) if ok_steps.size else None,
            "steps_max": int(ok_steps.max()) if ok_steps.size else None,
            "unreachable": float((stuck & ~solved).mean()),
            "timeout": float((~stuck & ~solved).mean()),
            "failed_episodes": np.flatnonzero(~solved)[:20].tolist(),  # key index (<= 20)
            "compile_s": round(compile_s, 2),
            "run_s": round(run_s, 2),
        })
    return rows


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", nargs="+", default=list(DEFAULT_TASKS))
    ap.add_argument("--episodes", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunk", type=int, default=1024, help="episodes per compiled batch")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results",
                                                  "craft_ceiling.json"))
    args = ap.parse_args(argv)
    rows = []
    for task in args.tasks:
        cap = C.STEP_CAP[C.TASKS[C.check_task(task)]]
        for row in play(task, args.episodes, args.seed, (None, cap // 2), args.chunk):
            rows.append(row)
            print(json.dumps(row), flush=True)
    out = {
        "what": "scripted Craft oracle on fresh maps (benchmarks/craft_ceiling.py)",
        "date": datetime.date.today().isoformat(),
        "machine": f"{platform.machine()} {os.cpu_count()}-core CPU, jax {jax.__version__} "
                   f"({jax.default_backend()})",
        "episodes": args.episodes,
        "seed": args.seed,
        "rows": rows,
    }
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    print()
    print("| task | cap | solved | success (mean return) | best return | below best "
          "| steps mean / median / p99 / max | unreachable | timeout |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        st = (f"{r['steps_mean']:.1f} / {r['steps_median']:.0f} / {r['steps_p99']:.0f} / "
              f"{r['steps_max']}" if r["steps_mean"] is not None else "-")
        print(f"| {r['task']} | {r['cap']} | {r['solved']:.4f} | {r['success']:.4f} | "
              f"{r['best_return']:.1f} | {r['below_best']:.4f} | {st} | {r['unreachable']:.4f} | "
              f"{r['timeout']:.4f} |")
    return out


if __name__ == "__main__":
    main()
