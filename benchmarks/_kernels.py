"""Where a compiled program's device time goes: its kernels, from a profiler trace.

``kernel_profile(call)`` runs ``call()`` (a compiled program on fixed inputs, already
warm) a few times under ``jax.profiler`` and reads the trace it writes (the Perfetto
JSON): per call, the kernels launched, the seconds the device's streams were busy with
them, and the kernels that took longest. On an accelerator, a program whose busy time is
close to its wall time and whose kernels are many and short is bound by their count (each
launch costs microseconds, however little it does), not by FLOPs; a CPU's trace holds no
device streams, so there the profile is empty. ``fused_computations(compiled)`` counts the
kernels XLA generates code for, on any backend.
"""
from __future__ import annotations

import collections
import glob
import gzip
import json
import re
import shutil
import tempfile
import time
from typing import Callable

import jax


def fused_computations(compiled) -> int:
    """The fused computations of a compiled program's optimized HLO: the kernels XLA
    generates code for, what its compile time follows."""
    return len(re.findall(r"^%fused\S* ", compiled.as_text(), re.M))


def kernel_profile(call: Callable[[], object], repeats: int = 3, top: int = 8) -> dict:
    """Per call of ``call``: wall seconds, kernels, device-busy seconds and the ``top``
    kernels by time (name, seconds, launches). ``{}`` where the trace has no device
    streams (a CPU)."""
    folder = tempfile.mkdtemp(prefix="smjax-kernels-")
    try:
        jax.block_until_ready(call())
        jax.profiler.start_trace(folder, create_perfetto_trace=True)
        t0 = time.perf_counter()
        for _ in range(repeats):
            jax.block_until_ready(call())
        wall = (time.perf_counter() - t0) / repeats
        jax.profiler.stop_trace()
        traces = glob.glob(f"{folder}/**/perfetto_trace.json.gz", recursive=True)
        if not traces:
            return {}
        with gzip.open(traces[0]) as f:
            trace = json.load(f)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    events = trace["traceEvents"] if isinstance(trace, dict) else trace
    meta = [e for e in events if e.get("ph") == "M"]
    processes = {e["pid"]: e["args"]["name"] for e in meta if e.get("name") == "process_name"}
    threads = {(e["pid"], e["tid"]): e["args"]["name"] for e in meta
               if e.get("name") == "thread_name"}
    by_kernel: dict = collections.defaultdict(lambda: [0, 0.0])
    for e in events:
        # a device stream's events: a "Stream" thread of a device's process (/device:GPU:0)
        if (e.get("ph") != "X" or "device:" not in processes.get(e["pid"], "").lower()
                or "stream" not in threads.get((e["pid"], e.get("tid")), "").lower()):
            continue
        by_kernel[e["name"]][0] += 1
        by_kernel[e["name"]][1] += e.get("dur", 0) * 1e-6
    if not by_kernel:
        return {}
    ranked = sorted(by_kernel.items(), key=lambda kv: -kv[1][1])[:top]
    return {"wall_seconds": wall,
            "kernels": sum(n for n, _ in by_kernel.values()) / repeats,
            "busy_seconds": sum(s for _, s in by_kernel.values()) / repeats,
            "top": [(name, s / repeats, n / repeats) for name, (n, s) in ranked]}


def describe(profile: dict) -> str:
    """The profile as a few lines for a terminal."""
    if not profile:
        return "   (no device kernels in the trace)"
    kernels, busy = profile["kernels"], profile["busy_seconds"]
    lines = [f"   {kernels:,.0f} kernels a call, busy {busy * 1e3:.1f} ms of "
             f"{profile['wall_seconds'] * 1e3:.1f} ms ({busy / max(kernels, 1) * 1e6:.1f} us a "
             f"kernel)"]
    lines += [f"     {s * 1e3:7.2f} ms {n:7.0f}x  {name[:90]}" for name, s, n in profile["top"]]
    return "\n".join(lines)
