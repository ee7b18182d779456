"""Suite-wide test settings.

One JAX persistent compilation cache per test session. Many tests compile the very same
XLA programs (the same training config run twice to compare numbers, a run that is killed
and resumed in another process, the same jitted env step in several files); with the cache
each distinct program is compiled once per session and later compiles of it load the
executable. The directory is fresh for every session and removed at its end, so every
program is still compiled (from scratch) at least once in every run of the suite. xdist
workers, training subprocesses and notebook kernels inherit it through the environment.
``SMJAX_TEST_COMPILE_CACHE=0`` turns it off.
"""
from __future__ import annotations

import os
import shutil
import tempfile

_VAR = "JAX_COMPILATION_CACHE_DIR"
_OWNER = "SMJAX_TEST_COMPILE_CACHE_OWNER"


def pytest_configure(config):
    if os.environ.get("SMJAX_TEST_COMPILE_CACHE", "1") == "0":
        return
    if _VAR not in os.environ:
        # the first process (the xdist controller, or the only one) makes the directory
        path = tempfile.mkdtemp(prefix="smjax-test-jax-cache-")
        os.environ[_VAR] = path
        os.environ[_OWNER] = str(os.getpid())
    import jax

    # jax reads the variable when imported; set it again in case jax was imported first
    jax.config.update("jax_compilation_cache_dir", os.environ[_VAR])


def pytest_unconfigure(config):
    if os.environ.get(_OWNER) == str(os.getpid()):
        shutil.rmtree(os.environ[_VAR], ignore_errors=True)
