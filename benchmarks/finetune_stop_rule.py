"""What the fine-tuning plateau rule's gain buys: episodes saved against success given up.

Fine-tuning ends when a block of ``finetune_plateau_episodes`` whole-task episodes gains less
than ``finetune_plateau_gain`` in mean task success over the block before (or at the gate, or
at the budget). Every results.json records, per seed, the means of the blocks it finished
(``finetune.block_means``), so a stricter gain can be replayed on runs made with a looser one:
the phase would have stopped at the first block whose rise is under the new gain. Replaying
gives, per task, the mean fine-tuning episodes and the mean task success of the last block
before the stop (the exploring policy's, a little under the final evaluation's).

Only gains at or above the one the runs used can be replayed (a looser rule would have run
past where they stopped), and only at the block size they used.

    python benchmarks/finetune_stop_rule.py benchmarks/results/craft_get_gem_*h100.json \
        --gains 0.01 0.015 0.02 0.03
"""
from __future__ import annotations

import argparse
import json
import statistics
from collections import defaultdict


def replay(block_means: list[float], episodes: int, block: int, gain: float):
    """(episodes, last block mean) of one seed's phase under ``gain``; ``None`` as the mean
    when the phase ended before its first block."""
    for k in range(1, len(block_means)):
        if block_means[k] - block_means[k - 1] < gain:
            return min(episodes, (k + 1) * block), block_means[k]
    return episodes, (block_means[-1] if block_means else None)


def seeds_of(path: str):
    """(task, block size, used gain, [(block_means, episodes)]) of one results file."""
    with open(path) as f:
        res = json.load(f)
    ft, cfg = res["finetune"], res["config"]
    rows = list(zip(ft["block_means"], ft["episodes"]))
    return res["task"], cfg["finetune_plateau_episodes"], cfg["finetune_plateau_gain"], rows


def table(paths: list[str], gains: list[float]) -> list[dict]:
    by_task = defaultdict(list)
    for path in paths:
        task, block, used, rows = seeds_of(path)
        by_task[(task, block, used)].extend(rows)
    out = []
    for (task, block, used), rows in sorted(by_task.items()):
        for gain in gains:
            if gain < used:
                continue
            replayed = [replay(bm, eps, block, gain) for bm, eps in rows]
            means = [m for _, m in replayed if m is not None]
            out.append({"task": task, "block": block, "gain": gain, "seeds": len(rows),
                        "episodes": statistics.mean(e for e, _ in replayed),
                        "last_block_mean": statistics.mean(means) if means else None,
                        "lowest_last_block": min(means) if means else None})
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", help="results.json files of runs with fine-tuning")
    ap.add_argument("--gains", type=float, nargs="+", default=[0.01, 0.015, 0.02, 0.03])
    args = ap.parse_args(argv)
    print("| task | seeds | block | gain | fine-tuning episodes (mean) "
          "| last block's task success (mean) | lowest |")
    print("|---|---|---|---|---|---|---|")
    for r in table(args.results, args.gains):
        mean = "-" if r["last_block_mean"] is None else f"{r['last_block_mean']:.3f}"
        low = "-" if r["lowest_last_block"] is None else f"{r['lowest_last_block']:.3f}"
        print(f"| {r['task']} | {r['seeds']} | {r['block']:,} | {r['gain']} "
              f"| {r['episodes']:,.0f} | {mean} | {low} |")


if __name__ == "__main__":
    main()
