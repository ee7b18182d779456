"""A pytest plugin that records, for each test, what JAX compiled in the test's process:
XLA compile seconds and count (and each compile of a second or more), persistent-cache
hits, and tracing and lowering seconds. ``PROBE_OUT=FILE python -m pytest -p
compile_probe ...`` (this folder on ``PYTHONPATH``) writes them as JSON after every test.
Compiles in a test's subprocesses (CLI runs, notebook kernels) are not counted."""
import json
import os

import jax

_current = ["<collection>"]
_records: dict = {}


def _record() -> dict:
    return _records.setdefault(_current[0], {"compile_s": 0.0, "n": 0, "big": [], "hits": 0,
                                             "trace_s": 0.0, "lower_s": 0.0})


def _duration(event: str, seconds: float, **_kwargs) -> None:
    record = _record()
    if event == "/jax/core/compile/backend_compile_duration":
        record["compile_s"] += seconds
        record["n"] += 1
        if seconds >= 1.0:
            record["big"].append(round(seconds, 2))
    elif event == "/jax/core/compile/jaxpr_trace_duration":
        record["trace_s"] += seconds
    elif event == "/jax/core/compile/jaxpr_to_mlir_module_duration":
        record["lower_s"] += seconds


def _event(event: str, **_kwargs) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _record()["hits"] += 1


jax.monitoring.register_event_duration_secs_listener(_duration)
jax.monitoring.register_event_listener(_event)


def pytest_runtest_setup(item):
    _current[0] = item.nodeid


def pytest_runtest_logfinish(nodeid, location):
    if os.environ.get("PROBE_OUT"):
        with open(os.environ["PROBE_OUT"], "w") as f:
            json.dump(_records, f)
