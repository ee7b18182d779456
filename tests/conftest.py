"""Suite-wide test settings. On the CPU most of this suite's time is XLA compiling programs
(a training run's chunk, gate and evaluation programs take ~10-30 s to compile and often
less to run), so both settings below cut compile time. Neither changes a program's HLO, but the second
changes its machine code and so float32 rounding: tests that compare two different programs
(vmapped vs unbatched, sharded vs not) compare floats with a tolerance, one step at a time
where the dynamics are chaotic (football), never bit for bit.

1. One JAX persistent compilation cache per test session. Many tests compile the very same
   XLA programs (the same training config run twice to compare numbers, a run that is
   killed and resumed in another process, the same jitted env step in several files); with
   the cache each distinct program is compiled once per session and later compiles of it
   load the executable. The directory is fresh for every session and removed at its end,
   so every program is still compiled (from scratch) at least once in every run of the
   suite. ``SMJAX_TEST_COMPILE_CACHE=0`` turns it off.
2. ``jax_disable_most_optimizations`` (JAX's own switch for when optimizing costs more
   than it saves): XLA's LLVM backend compiles at optimization level 0. The programs
   (HLO) are the ones users run; their machine code is less optimized, which here makes
   compiles about a third faster and the (short) runs a little slower. ``SMJAX_TEST_FAST_COMPILE=0``
   compiles with XLA's default optimizations instead.

xdist workers, training subprocesses and notebook kernels inherit both through the
environment.
"""
from __future__ import annotations

import os
import shutil
import tempfile

_VAR = "JAX_COMPILATION_CACHE_DIR"
_OWNER = "SMJAX_TEST_COMPILE_CACHE_OWNER"


def pytest_configure(config):
    import jax

    if os.environ.get("SMJAX_TEST_FAST_COMPILE", "1") != "0":
        os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")
        jax.config.update("jax_disable_most_optimizations",
                          os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"].lower()
                          in ("1", "y", "yes", "t", "true", "on"))
    if os.environ.get("SMJAX_TEST_COMPILE_CACHE", "1") == "0":
        return
    if _VAR not in os.environ:
        # the first process (the xdist controller, or the only one) makes the directory
        path = tempfile.mkdtemp(prefix="smjax-test-jax-cache-")
        os.environ[_VAR] = path
        os.environ[_OWNER] = str(os.getpid())
    # jax reads the variable when imported; set it again in case jax was imported first
    jax.config.update("jax_compilation_cache_dir", os.environ[_VAR])


def pytest_unconfigure(config):
    if os.environ.get(_OWNER) == str(os.getpid()):
        shutil.rmtree(os.environ[_VAR], ignore_errors=True)
