"""Summary statistics shared by the benchmark scripts (population std, as RESULTS.md quotes)."""
from __future__ import annotations

import statistics


def mean_std(values: list[float]) -> tuple[float, float]:
    """Mean and population standard deviation (0 for a single value)."""
    return statistics.mean(values), (statistics.pstdev(values) if len(values) > 1 else 0.0)


def reached_summary(values: list) -> str:
    """'mean +- std (reached/seeds)' over the seeds that reached the threshold (None: not)."""
    got = [v for v in values if v is not None]
    if not got:
        return f"not reached (0/{len(values)})"
    mean, std = mean_std(got)
    return f"{mean:,.0f} +- {std:,.0f} ({len(got)}/{len(values)})"
