"""Each persistent-cache read of a command, with its start, seconds, thread and program:
``python benchmarks/results/cache_compression/reads_by_thread.py train ...`` runs the CLI
in-process with JAX's cache read timed (printed to stderr at the end)."""
import os
import sys
import threading
import time

from jax._src import compiler

_read = compiler._cache_read
_start = time.perf_counter()
_reads = []


def _timed_read(module_name, *args, **kwargs):
    t = time.perf_counter()
    out = _read(module_name, *args, **kwargs)
    _reads.append((t - _start, time.perf_counter() - t, threading.current_thread().name,
                   module_name))
    return out


compiler._cache_read = _timed_read

from smjax.cli import main  # noqa: E402 (after the patch, so every read is timed)

code = main(sys.argv[1:])
for start, seconds, thread, name in _reads:
    print(f"{start:7.2f} {seconds:6.3f} {thread[:22]:22s} {name}", file=sys.stderr)
sys.stderr.flush()
os._exit(code)
