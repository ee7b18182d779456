"""Shared timing and reporting helpers of the peer benchmarks (not a public API).

Every script times compilation separately (``lower(...).compile()``) and then runs the
compiled program ``repeats`` times, reporting the median wall time; results carry the
host's load average because the CPU numbers are taken on a shared machine.
"""
from __future__ import annotations

import json
import os
import platform
import statistics
import time
from importlib import metadata
from typing import Any, Callable

import jax


def versions(*packages: str) -> dict[str, str]:
    """Installed versions of ``packages`` (``"missing"`` when not installed)."""
    out = {}
    for name in ("jax", "jaxlib", "flax", "optax") + packages:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "missing"
    return out


def machine() -> dict[str, Any]:
    device = jax.devices()[0]
    return {
        "backend": jax.default_backend(),
        "device": getattr(device, "device_kind", str(device)),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "loadavg_1_5_15": list(os.getloadavg()),
    }


def compile_and_time(fn: Callable, args: tuple, repeats: int) -> dict[str, Any]:
    """Compile ``jax.jit(fn)`` for ``args`` (timed), then time ``repeats`` runs.

    Returns ``compile_s``, every run's seconds, their median and the last run's output.
    ``repeats`` below 1 raises ValueError.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - start
    runs, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(*args))
        runs.append(time.perf_counter() - start)
    return {"compile_s": compile_s, "run_s": runs, "median_s": statistics.median(runs), "output": out}


def compile_and_time_interleaved(programs: dict[str, tuple[Callable, tuple]], repeats: int) -> dict:
    """``compile_and_time`` for several programs, with their timed runs alternating.

    On a shared machine the load drifts; alternating A, B, A, B... spreads the drift
    over all programs instead of charging it to whichever ran last.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    compiled, results = {}, {}
    for name, (fn, args) in programs.items():
        start = time.perf_counter()
        compiled[name] = jax.jit(fn).lower(*args).compile()
        results[name] = {"compile_s": time.perf_counter() - start, "run_s": [], "output": None}
        jax.block_until_ready(compiled[name](*args))  # warm-up run, untimed
    for _ in range(repeats):
        for name, (_, args) in programs.items():
            start = time.perf_counter()
            results[name]["output"] = jax.block_until_ready(compiled[name](*args))
            results[name]["run_s"].append(time.perf_counter() - start)
    for result in results.values():
        result["median_s"] = statistics.median(result["run_s"])
    return results


def write_json(path: str, payload: dict) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(payload, f, indent=2, default=float)


def print_table(header: list[str], rows: list[list[Any]]) -> None:
    """A markdown table on stdout (pastes into RESULTS files as is)."""
    fmt = lambda v: f"{v:,.0f}" if isinstance(v, float) and abs(v) >= 100 else (  # noqa: E731
        f"{v:.3g}" if isinstance(v, float) else str(v))
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(fmt(v) for v in row) + " |")
