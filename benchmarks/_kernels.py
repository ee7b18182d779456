"""Where a compiled program's device time goes: its kernels, from a profiler trace.

``kernel_profile(call)`` runs ``call()`` (a compiled program on fixed inputs, already
warm) a few times under ``jax.profiler`` and reads the trace it writes (the Perfetto
JSON): per call, the kernels launched, the seconds the device's streams were busy with
them, and the kernels that took longest. On an accelerator, a program whose busy time is
close to its wall time and whose kernels are many and short is bound by their count (each
launch costs microseconds, however little it does), not by FLOPs; a CPU's trace holds no
device streams, so there the profile is empty. ``fused_computations(hlo)`` counts the
kernels XLA generates code for, on any backend, and ``kernels_by_source(hlo)`` says which
source lines they come from (``hlo``: a compiled program's ``as_text()``, which can be
megabytes, so a caller dumps it once for both).
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


def fused_computations(hlo: str) -> int:
    """The fused computations of a compiled program's optimized HLO text: the kernels XLA
    generates code for, what its compile time follows."""
    return len(re.findall(r"^%fused\S* ", hlo, re.M))


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


# what launches work in a compiled program: fused kernels and the unfused operations XLA
# runs as kernels of their own (copies, library calls, scatters, ...)
_LAUNCHES = ("fusion", "custom-call", "copy", "scatter", "gather", "sort", "concatenate",
             "dynamic-update-slice", "dynamic-slice", "reduce", "transpose", "pad", "slice")


def _source_lines(text: str) -> dict:
    """stack frame id -> [(file, function, line), ...] innermost first, from the optimized
    HLO's FileNames / FunctionNames / FileLocations / StackFrames tables."""
    def table(name: str, nxt: str) -> str:
        start = text.find(f"\n{name}\n")
        return "" if start < 0 else text[start:text.find(f"\n{nxt}\n", start + 1)]

    files = dict(re.findall(r'^(\d+) "([^"]*)"$', table("FileNames", "FunctionNames"), re.M))
    funcs = dict(re.findall(r'^(\d+) "([^"]*)"$', table("FunctionNames", "FileLocations"),
                            re.M))
    locs = {i: (files.get(f, "?"), funcs.get(fn, "?"), int(line)) for i, f, fn, line in
            re.findall(r"^(\d+) \{file_name_id=(\d+) function_name_id=(\d+) line=(\d+)",
                       table("FileLocations", "StackFrames"), re.M)}
    parents = {i: (loc, parent) for i, loc, parent in
               re.findall(r"^(\d+) \{file_location_id=(\d+) parent_frame_id=(\d+)", text, re.M)}

    def chain(frame: str) -> list:
        out, seen = [], set()
        while frame in parents and frame not in seen:
            seen.add(frame)
            loc, frame = parents[frame]
            out.append(locs.get(loc, ("?", "?", 0)))
        return out

    return {frame: chain(frame) for frame in parents}


def kernels_by_source(hlo: str, package: str = "/smjax/") -> collections.Counter:
    """A compiled program's launches, from its optimized HLO text (fusions and unfused
    kernels of every computation that is not itself fused), counted by source line: the
    innermost frame in ``package`` (else the innermost frame at all), as ``path:line
    function``. Each launch counts once however often its loop runs; XLA names no source
    for some (copies it inserts)."""
    called = set(re.findall(r"(?:calls|to_apply)=%([^,\s}]+)", hlo))
    frames = _source_lines(hlo)
    counts: collections.Counter = collections.Counter()
    for computation in re.split(r"\n(?=\S)", hlo):
        name = re.match(r"(?:ENTRY )?%(\S+)", computation)
        if not name or name.group(1) in called:
            continue
        for line in computation.splitlines()[1:]:
            op = re.search(r"= (?:\([^=]*\)|\S+) ([a-z-]+)\(", line)
            if not op or op.group(1) not in _LAUNCHES:
                continue
            frame = re.search(r"stack_frame_id=(\d+)", line)
            chain = frames.get(frame.group(1), []) if frame else []
            mine = [f for f in chain if package in f[0]] or chain
            if mine:
                path, function, number = mine[0]
                path = (path.split(package, 1)[-1] if package in path else
                        path.split("site-packages/")[-1] if "site-packages/" in path else
                        "/".join(path.split("/")[-2:]))
                counts[f"{path}:{number} {function}"] += 1
            else:
                counts[f"({op.group(1)}, no source)"] += 1
    return counts
