"""Checkpoints: arrays with orbax, host-side counters as JSON, swapped in atomically.

Layout of ``DIR/checkpoints``: ``step-N/`` (an orbax checkpoint of the array state; a
re-save of chunk N while ``step-N`` is in force goes to ``step-N.1``, ``step-N.2``, ...)
and ``latest.json`` (the host state and the name of the newest complete step).

Every save runs the same sequence, so the last good checkpoint survives a kill at any
instant, a full disk and a write error:

1. the arrays are written under a name nothing points at (never the step in force);
2. every file of it and its directories are fsynced;
3. ``latest.json`` is replaced atomically (temporary file, fsync, rename, fsync of the
   directory);
4. only then are older steps (and leftovers of interrupted saves) deleted.

With several processes only process 0 touches the directory: the trainer gathers the
arrays to host numpy first, orbax runs on process 0 alone (its barriers limited to that
process), and on resume process 0 reads and broadcasts (``shared_meta``, the trainer's
``restore``). The files are the same as a single process writes, so either kind of run
resumes the other's checkpoints.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

import jax

from smjax.train import distributed as dist
from smjax.train.results import atomic_write_text, fsync_dir

LATEST = "latest.json"


class CheckpointError(RuntimeError):
    """A checkpoint cannot be written or read; the message names the path and what to do."""


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


def _first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0] if text else ''}"[:300]


def _check_writable(root: Path) -> None:
    """Fail fast and in one line: orbax's writer threads hang for minutes on a read-only
    directory before they give up."""
    try:
        root.mkdir(parents=True, exist_ok=True)
        probe = root / f".write-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        raise CheckpointError(f"cannot write checkpoints to {root}: {err.strerror or err}; "
                              f"make it writable or choose another --out") from None


def _fresh_name(root: Path, step: int, in_force: str | None) -> str:
    """``step-N`` unless it is the step ``latest.json`` points at (then a numbered variant):
    a re-save of the same chunk must never overwrite the checkpoint in force."""
    name, k = f"step-{step}", 0
    while name == in_force:
        k += 1
        name = f"step-{step}.{k}"
    return name


def _fsync_tree(path: Path) -> None:
    """Flush every file and directory of a finished step before anything points at it."""
    for dirpath, _, files in os.walk(path):
        for f in files:
            fd = os.open(os.path.join(dirpath, f), os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        fsync_dir(Path(dirpath))
    fsync_dir(path.parent)


def _prune(root: Path, keep: str) -> None:
    """Delete every step but ``keep`` and the temporaries of interrupted saves."""
    for old in root.iterdir():
        stale_step = old.name.startswith("step-") and old.name != keep
        stale_tmp = ".orbax-checkpoint-tmp" in old.name or old.name.startswith(f".{LATEST}.")
        if stale_step or stale_tmp:
            if old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
            else:
                old.unlink(missing_ok=True)


def _in_force(root: Path) -> str | None:
    try:
        return json.loads((root / LATEST).read_text()).get("path")
    except (OSError, ValueError, AttributeError):
        return None


def save_checkpoint(out_dir: str | Path, step: int, arrays: Any, meta: dict) -> Path:
    """Write a checkpoint of ``arrays`` and ``meta``; returns the new step's directory."""
    root = checkpoint_dir(out_dir).resolve()
    _check_writable(root)
    target = root / _fresh_name(root, step, _in_force(root))
    if target.exists():  # an unreferenced leftover of an interrupted save
        shutil.rmtree(target)
    try:
        checkpointer = _checkpointer()
        checkpointer.save(target, _flat(arrays))
        checkpointer.wait_until_finished()
        _fsync_tree(target)
        atomic_write_text(root / LATEST,
                          json.dumps({"step": step, "path": target.name, "meta": meta}))
    except Exception as err:  # disk full, I/O error: the previous checkpoint stays in force
        if _in_force(root) != target.name:
            shutil.rmtree(target, ignore_errors=True)
        raise CheckpointError(f"could not write checkpoint {target} ({_first_line(err)}); the "
                              f"previous checkpoint in {root} is kept") from err
    _prune(root, keep=target.name)
    return target


def load_meta(out_dir: str | Path) -> dict | None:
    """``latest.json``'s content (None when there is none); a damaged one is refused in one
    line naming the file."""
    latest = checkpoint_dir(out_dir) / LATEST
    if not latest.exists():
        return None
    fix = "restore it from a backup, or start again with --overwrite"
    try:
        info = json.loads(latest.read_text())
    except (OSError, ValueError) as err:
        raise CheckpointError(f"{latest} is unreadable or not valid JSON ({_first_line(err)}); "
                              f"{fix}") from None
    ok = (isinstance(info, dict) and isinstance(info.get("path"), str)
          and isinstance(info.get("meta"), dict) and isinstance(info["meta"].get("run"), dict)
          and isinstance(info["meta"].get("host"), dict))
    if not ok:
        raise CheckpointError(f"{latest} is not a smjax checkpoint index (missing path/meta); {fix}")
    if not (checkpoint_dir(out_dir) / info["path"]).is_dir():
        raise CheckpointError(f"{latest} points at {info['path']}, which does not exist; {fix}")
    return info


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
    try:
        restored = _checkpointer().restore(path, abstract)
    except Exception as err:  # truncated or corrupt data: orbax chains a long traceback
        raise CheckpointError(f"checkpoint data in {path} cannot be read ({_first_line(err)}); "
                              f"it is truncated or corrupt: restore it or start again with "
                              f"--overwrite") from None
    leaves, treedef = jax.tree.flatten(like)
    return jax.tree.unflatten(
        treedef, [restored[str(i)] if x.size > 0 else x for i, x in enumerate(leaves)])
