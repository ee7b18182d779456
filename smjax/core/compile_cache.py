"""JAX's persistent compilation cache, on by default for smjax's training and benchmarks.

Compiling a training run's programs takes tens of seconds on a CPU, often longer than
running them; with the cache a second run of the same configuration (a notebook cell run
again, the same CLI command, another seed set of the same shapes) loads the compiled
executables from disk instead.

Where the cache lives:

* ``JAX_COMPILATION_CACHE_DIR`` (or ``jax.config.update("jax_compilation_cache_dir",
  ...)``) set by the user: that directory;
* otherwise ``$SMJAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/smjax/jax``, else
  ``~/.cache/smjax/jax``.

Small programs are cached too (JAX's default keeps only those that took a second or more
to compile, and a run has dozens of smaller ones), unless the user set
``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` or the config value themselves.
``SMJAX_COMPILATION_CACHE=0`` (or ``false``/``off``/``no``) turns it off. Entries are
keyed by JAX on the program, the JAX/XLA versions and the device, so a stale entry is
never used for a different program; the directory can be deleted at any time.
"""
from __future__ import annotations

import os
from pathlib import Path

import jax

_OFF = ("0", "false", "off", "no")
_JAX_MIN_COMPILE_TIME = 1.0  # JAX's default threshold (seconds) for caching a program


def default_cache_dir() -> Path:
    if os.environ.get("SMJAX_CACHE_DIR"):
        return Path(os.environ["SMJAX_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "smjax" / "jax"


def enable_compilation_cache() -> str | None:
    """Turn the persistent cache on unless the user opted out; returns its directory.

    Idempotent. Honours a directory the user already chose. Programs compiled before this
    call (in the same process) are not cached, later ones are.
    """
    if os.environ.get("SMJAX_COMPILATION_CACHE", "1").strip().lower() in _OFF:
        return None
    path = jax.config.jax_compilation_cache_dir
    if not path:
        path = default_cache_dir()
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError:
            return None  # an unwritable home must not stop training; it only loses the cache
        jax.config.update("jax_compilation_cache_dir", str(path))
    # Cache small programs too: a run compiles many (inits, evaluation, gate) and each
    # costs the user seconds on a CPU. A threshold the user chose stays.
    if (jax.config.jax_persistent_cache_min_compile_time_secs == _JAX_MIN_COMPILE_TIME
            and "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ):
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    _forget_earlier_decision()
    return str(path)


def _forget_earlier_decision() -> None:
    """JAX decides once per process whether the cache is used, at the first compile; if
    something compiled before the directory was set, make it decide again."""
    try:
        from jax._src import compilation_cache as cc
    except ImportError:  # a JAX without the module: the setting applies from the start
        return
    if getattr(cc, "_cache_checked", False) and not getattr(cc, "_cache_used", True):
        cc.reset_cache()
