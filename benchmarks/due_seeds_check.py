"""A gate of a few due seeds of many, run as the whole batch and as a batch of 16
(``smjax.train.episode_calls``), on this device: the largest difference between the due
seeds' results (0 where the two agree exactly).

    python benchmarks/due_seeds_check.py --seeds 100
"""
from __future__ import annotations

import argparse
import types

import jax
import numpy as np

from profile_training import build
from smjax.train.episode_calls import BUCKET, EpisodeCalls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--task", default="craft/get_gem")
    ap.add_argument("--seeds", type=int, default=64)
    a = ap.parse_args()
    args = types.SimpleNamespace(task=a.task, env=[], method="top-down", algo="ppo",
                                 seeds=a.seeds, num_envs=128, rollout_ticks=32, updates=4,
                                 level=1)
    _, _, _, _, engine, plan, state, bank, learned, keys = build(args)
    S = a.seeds
    for due_seeds in ([0, 5, 9], list(range(0, S, max(1, S // 12)))[:12]):
        due = [s in due_seeds for s in range(S)]
        for threshold in (0.8, 0.05):
            results = {}
            for name, bucket in (("whole", S), ("small", BUCKET)):
                engine.episode_calls = EpisodeCalls(engine.compile_episodes, True, bucket)
                r, _ = engine.gate(keys, state, bank, learned, [plan.option] * S,
                                   [plan.start] * S, due, [threshold] * S)
                results[name] = {k: np.asarray(v)[due_seeds] for k, v in jax.device_get(r).items()}
            diff = {k: float(np.max(np.abs(results["whole"][k] - results["small"][k])))
                    for k in results["whole"]}
            print(f"{len(due_seeds)} due of {S}, threshold {threshold}: largest difference "
                  f"{diff}; success {[round(float(x), 3) for x in results['whole']['success']]}")


if __name__ == "__main__":
    main()
