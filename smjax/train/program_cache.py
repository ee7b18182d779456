"""A run's large programs saved as StableHLO, so that a repeated run does not trace them.

JAX's persistent cache (:mod:`smjax.core.compile_cache`) skips XLA's compile, but every run
still traces and lowers its programs from Python first: seconds for the training chunk and
the episodes program on a CPU, paid again by every repeated command. A program whose every
input is named here is exported (``jax.export``) at its first compile, and a later run with
the same key loads the export and compiles it (a hit in JAX's cache) without tracing:

* the run's identity (registered task, environment overrides, every config field, sweep),
* the program's name and its arguments' shapes, dtypes and layout,
* the source of the whole smjax package, the JAX and jaxlib versions, the device, the
  XLA flags and the JAX settings that change what is compiled.

A run whose programs depend on code outside smjax (a user's environment or hierarchy
object) passes no identity, and is traced every time. Entries live beside JAX's cache, under
``smjax-programs/``, and go with it (``SMJAX_COMPILATION_CACHE=0`` turns both off); a file
that fails to load is deleted and the program traced again.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import pickle
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.timeline import TIMELINE
from smjax.core.files import atomic_write_bytes

_SETTINGS = ("jax_enable_x64", "jax_disable_most_optimizations", "jax_default_matmul_precision",
             "jax_default_prng_impl", "jax_threefry_partitionable")


@functools.cache
def source_digest() -> str:
    """sha256 of every Python file of the smjax package (path and contents)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _platform() -> dict:
    import jaxlib

    device = jax.devices()[0]
    return {"jax": jax.__version__, "jaxlib": jaxlib.__version__, "platform": device.platform,
            "device_kind": device.device_kind, "devices": jax.device_count(),
            "xla_flags": os.environ.get("XLA_FLAGS", ""),
            "settings": {k: str(getattr(jax.config, k, None)) for k in _SETTINGS}}


def program_key(identity: dict, name: str, args: tuple) -> str:
    """What a saved program must match to be loaded in place of compiling ``name``."""
    leaves, tree = jax.tree.flatten(args)
    shapes = [(getattr(x, "shape", None), str(getattr(x, "dtype", type(x).__name__)),
               str(getattr(x, "sharding", "")), getattr(x, "weak_type", None)) for x in leaves]
    text = json.dumps({"identity": identity, "name": name, "tree": str(tree), "args": shapes,
                       "smjax": source_digest(), "platform": _platform()},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _directory() -> Path | None:
    base = jax.config.jax_compilation_cache_dir
    return Path(base) / "smjax-programs" if base else None


def compile_program(jitted, args: tuple, name: str, identity: dict | None,
                    static: tuple = (), donate: tuple = ()):
    """``jitted.lower(*args, *static).compile()``, or the same program loaded as StableHLO
    from an earlier run with the same key, compiled (a hit in JAX's persistent cache)
    without tracing (``identity`` None: always traced). ``donate``: the positions of
    ``args`` whose buffers the program may reuse, as ``jitted`` declares them."""
    folder = _directory() if identity is not None else None
    if folder is None:
        return jitted.lower(*args, *static).compile()
    path = folder / f"{program_key(identity, name, args + static)}.bin"
    leaves, in_tree = jax.tree.flatten(args)
    donated = _donated_leaves(args, donate)
    saved = _load(path)
    if saved is not None:
        exported, out_tree = saved
        TIMELINE.count("programs loaded as StableHLO (no tracing)")
    else:
        trees = []

        def flat(*xs):  # exported programs take and give flat lists of arrays
            out, tree = jax.tree.flatten(jitted(*jax.tree.unflatten(in_tree, xs), *static))
            trees.append(tree)
            return out

        exported = jax.export.export(jax.jit(flat))(*leaves)
        out_tree = trees[0]
        _save(path, exported, out_tree)
    compiled = jax.jit(exported.call, donate_argnums=donated).lower(*leaves).compile()
    return _Unflattened(compiled, out_tree)


class SavedOnFirstCall:
    """``jitted`` called as usual, except that its first call with arrays (not tracers)
    for a set of shapes compiles through :func:`compile_program`, so that a repeated run
    loads that program without tracing it; later calls with those shapes run it. Under a
    trace (``jax.eval_shape``, an enclosing ``jit``), or where ``identity_of()`` gives
    None, it is ``jitted`` itself. For a run's start-up programs (a learner's init, the
    environments' reset), whose tracing costs a repeated run tenths of a second each."""

    def __init__(self, jitted, name: str, identity_of):
        self._jitted, self._name, self._identity_of = jitted, name, identity_of
        self._programs: dict = {}

    def __call__(self, *args):
        # a host array as the device array it becomes: one program for both
        args = jax.tree.map(lambda x: jnp.asarray(x) if isinstance(x, np.ndarray) else x, args)
        leaves, tree = jax.tree.flatten(args)
        identity = self._identity_of()
        if identity is None or any(isinstance(x, jax.core.Tracer) for x in leaves):
            return self._jitted(*args)
        shapes = (tree, tuple((x.shape, str(x.dtype), str(getattr(x, "sharding", "")))
                              for x in leaves))
        program = self._programs.get(shapes)
        if program is None:
            program = self._programs[shapes] = compile_program(self._jitted, args, self._name,
                                                               identity)
        return program(*args)


class _Unflattened:
    """A program over flat leaves, called with the original arguments' structure."""

    def __init__(self, compiled, out_tree):
        self._compiled, self._out_tree = compiled, out_tree

    def __call__(self, *args):
        return jax.tree.unflatten(self._out_tree, self._compiled(*jax.tree.leaves(args)))


def _donated_leaves(args: tuple, donate: tuple) -> tuple:
    out, offset = [], 0
    for i, a in enumerate(args):
        n = len(jax.tree.leaves(a))
        if i in donate:
            out.extend(range(offset, offset + n))
        offset += n
    return tuple(out)


def _load(path: Path):
    if not path.is_file():
        return None
    try:
        blob, out_tree = pickle.loads(path.read_bytes())
        return jax.export.deserialize(bytearray(blob)), out_tree
    except Exception:  # noqa: BLE001 - a damaged or foreign entry: trace instead
        path.unlink(missing_ok=True)
        return None


def _save(path: Path, exported, out_tree) -> None:
    """Best effort: a program that cannot be serialized or a full disk only loses the
    saving, never the run."""
    try:
        blob = pickle.dumps((bytes(exported.serialize()), out_tree))
        atomic_write_bytes(path, blob, durable=False)  # a lost entry is traced again
    except Exception:  # noqa: BLE001
        return


def cacheable_identity(task: Any, given_hierarchy: Any, identity: dict) -> dict | None:
    """The identity that keys a run's programs, or None where something the programs
    depend on is not named by it: a task given as objects, a hierarchy object, a task
    registered outside smjax, or several devices (the layout varies)."""
    from smjax.core.registry import get_entry

    if not isinstance(task, str) or given_hierarchy is not None or jax.device_count() != 1:
        return None
    if not get_entry(task).factory.__module__.startswith("smjax."):
        return None
    return {k: v for k, v in identity.items() if k != "seeds"}
