"""Checkpoints: arrays with orbax, host-side counters as JSON, swapped in atomically.

Layout of ``DIR/checkpoints``: ``step-N/`` (an orbax checkpoint of the array state) and
``latest.json`` (the host state and the name of the newest complete ``step-N``).
``latest.json`` is replaced only after orbax has finished writing, so a crash at any
moment leaves the previous good checkpoint in force; older steps are then deleted.

With several processes only process 0 touches the directory: the trainer gathers the
arrays to host numpy first, orbax runs on process 0 alone (its barriers limited to that
process), and on resume process 0 reads and broadcasts (``shared_meta``, the trainer's
``restore``). The files are the same as a single process writes, so either kind of run
resumes the other's checkpoints.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import jax

from smjax.train import distributed as dist
from smjax.train.results import atomic_write_text

LATEST = "latest.json"


def checkpoint_dir(out_dir: str | Path) -> Path:
    return Path(out_dir) / "checkpoints"


def _flat(arrays: Any) -> dict:
    """Leaves by position, without zero-size ones (orbax refuses them; e.g. MJX's empty
    ``act``): restoring takes those from the template, where they are empty as well."""
    return {str(i): x for i, x in enumerate(jax.tree.leaves(arrays)) if x.size > 0}


def _checkpointer():
    import orbax.checkpoint as ocp

    if not dist.is_multiprocess():
        return ocp.StandardCheckpointer()
    # only process 0 calls orbax; without this its barriers would wait for the others
    only_writer = ocp.options.MultiprocessingOptions(primary_host=0, active_processes={0})
    return ocp.StandardCheckpointer(multiprocessing_options=only_writer)


def save_checkpoint(out_dir: str | Path, step: int, arrays: Any, meta: dict) -> Path:
    root = checkpoint_dir(out_dir).resolve()
    root.mkdir(parents=True, exist_ok=True)
    target = root / f"step-{step}"
    if target.exists():  # leftover of a crash before latest.json pointed at it
        shutil.rmtree(target)
    checkpointer = _checkpointer()
    checkpointer.save(target, _flat(arrays))
    checkpointer.wait_until_finished()
    atomic_write_text(root / LATEST, json.dumps({"step": step, "path": target.name, "meta": meta}))
    for old in root.glob("step-*"):
        if old.name != target.name:
            shutil.rmtree(old, ignore_errors=True)
    return target


def load_meta(out_dir: str | Path) -> dict | None:
    latest = checkpoint_dir(out_dir) / LATEST
    if not latest.exists():
        return None
    return json.loads(latest.read_text())


def shared_meta(out_dir: str | Path) -> dict | None:
    """``load_meta`` as process 0 sees it, on every process (collective when several)."""
    if not dist.is_multiprocess():
        return load_meta(out_dir)
    return dist.broadcast_json(load_meta(out_dir) if dist.is_writer() else None)


def load_arrays(out_dir: str | Path, like: Any) -> Any:
    import orbax.checkpoint as ocp

    info = load_meta(out_dir)
    if info is None:
        raise FileNotFoundError(f"no checkpoint in {checkpoint_dir(out_dir)}")
    if dist.is_multiprocess():
        # process 0 alone reads, into host numpy (``like`` holds numpy), then broadcasts
        abstract = _flat(like)
    else:
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, _flat(like))
    path = (checkpoint_dir(out_dir) / info["path"]).resolve()
    restored = _checkpointer().restore(path, abstract)
    leaves, treedef = jax.tree.flatten(like)
    return jax.tree.unflatten(
        treedef, [restored[str(i)] if x.size > 0 else x for i, x in enumerate(leaves)])
