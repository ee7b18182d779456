"""Where a command's wall time goes, from process start to the last file written.

A user waits for the whole command, not only for the training clock: interpreter and
imports, building the environment and hierarchy, tracing, lowering and compiling (or
loading from the persistent cache), the chunks, gates, evaluation, checkpoints and the
files at the end. ``TIMELINE`` records named spans (summed when a label repeats) and,
through ``jax.monitoring``, JAX's own tracing / lowering / compiling / cache-load seconds,
which happen inside those spans. ``smjax train --profile`` prints ``TIMELINE.report()``
and writes ``TIMELINE.to_dict()`` to ``OUT/profile.json``.

Recording costs two ``perf_counter`` calls per span, so it is always on.
"""
from __future__ import annotations

import contextlib
import os
import time

# JAX's duration events (seconds), by the name the report gives them
_JAX_DURATIONS = {
    "/jax/core/compile/jaxpr_trace_duration": "jax: tracing",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "jax: lowering to StableHLO",
    "/jax/core/compile/backend_compile_duration": "jax: XLA compile or cache load",
    "/jax/compilation_cache/cache_retrieval_time_sec": "jax: persistent-cache reads",
}
_JAX_COUNTS = {
    "/jax/compilation_cache/cache_hits": "persistent-cache hits",
    "/jax/compilation_cache/cache_misses": "persistent-cache misses",
}


def _process_start() -> float:
    """The process's start on the ``perf_counter`` clock (Linux: from /proc; elsewhere:
    when this module was imported)."""
    now = time.perf_counter()
    try:
        with open("/proc/self/stat") as f:
            start_ticks = int(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        age = uptime - start_ticks / os.sysconf("SC_CLK_TCK")
        return now - age if 0 <= age < 3600 else now
    except (OSError, ValueError, IndexError, AttributeError):
        return now


class Timeline:
    """Named spans of one process, plus JAX's compile-stage totals."""

    def __init__(self, start: float | None = None):
        self.start = _process_start() if start is None else start
        self.spans: dict[str, list[float]] = {}  # label -> [first start, total s, count]
        self.jax: dict[str, list[float]] = {}    # label -> [total s, count]
        self._listening = False

    def now(self) -> float:
        """Seconds since the process started."""
        return time.perf_counter() - self.start

    def add(self, label: str, began: float, seconds: float) -> None:
        """Record ``seconds`` under ``label`` (``began``: seconds since process start)."""
        entry = self.spans.setdefault(label, [began, 0.0, 0])
        entry[1] += seconds
        entry[2] += 1

    def inside(self, label: str, seconds: float) -> None:
        """``seconds`` of work that ran beside the phases (a background thread's), listed
        with JAX's totals so that the phases still add up to the whole command."""
        entry = self.jax.setdefault(label, [0.0, 0])
        entry[0] += seconds
        entry[1] += 1

    def count(self, label: str) -> None:
        """One more of ``label`` (an event without a duration), listed with JAX's totals."""
        self.jax.setdefault(label, [0.0, 0])[1] += 1

    @contextlib.contextmanager
    def span(self, label: str):
        began = self.now()
        try:
            yield
        finally:
            self.add(label, began, self.now() - began)

    def listen_to_jax(self) -> None:
        """Sum JAX's tracing, lowering and compile events from now on (once per process)."""
        if self._listening:
            return
        import jax.monitoring

        def on_duration(event: str, seconds: float, **_):
            if event in _JAX_DURATIONS:
                entry = self.jax.setdefault(_JAX_DURATIONS[event], [0.0, 0])
                entry[0] += seconds
                entry[1] += 1

        def on_event(event: str, **_):
            if event in _JAX_COUNTS:
                self.jax.setdefault(_JAX_COUNTS[event], [0.0, 0])[1] += 1

        jax.monitoring.register_event_duration_secs_listener(on_duration)
        jax.monitoring.register_event_listener(on_event)
        self._listening = True

    def to_dict(self) -> dict:
        spans = sorted(self.spans.items(), key=lambda kv: kv[1][0])
        return {"total_seconds": self.now(),
                "spans": [{"label": k, "start": v[0], "seconds": v[1], "count": v[2]}
                          for k, v in spans],
                "jax": {k: {"seconds": v[0], "count": v[1]} for k, v in self.jax.items()}}

    def report(self) -> str:
        """A table: each span's start and total seconds, then JAX's totals."""
        d = self.to_dict()
        rows = [f"{'phase':<44} {'starts at':>9} {'seconds':>8} {'times':>6}"]
        rows += [f"{s['label']:<44} {s['start']:>9.2f} {s['seconds']:>8.2f} {s['count']:>6}"
                 for s in d["spans"]]
        rows.append(f"{'whole command so far':<44} {'':>9} {d['total_seconds']:>8.2f}")
        if d["jax"]:
            rows.append("inside the phases above:")
            rows += [f"  {k:<42} {'':>9} {v['seconds']:>8.2f} {v['count']:>6}"
                     for k, v in d["jax"].items()]
        return "\n".join(rows)


TIMELINE = Timeline()
