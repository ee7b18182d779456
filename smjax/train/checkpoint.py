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
4. only then are older steps (and leftovers of interrupted saves) deleted; the step that
   was in force before stays as the previous good one.

Every step carries a manifest (``smjax.train.manifest``: its host state and the sha256 of
its files), which a resume verifies; a step can be resumed from its manifest alone (no
``latest.json``, or ``step=`` naming an older step: ``--resume-from``). A resume reads
``CHECKPOINT_FORMAT`` alone: a checkpoint of another format is refused before its fields are
read (``load_meta``), so it never resumes into a trainer laid out for other arrays.

A save that fails (read-only or full file system, I/O error) raises ``CheckpointError``
at once, in one line: the folder is probed first, orbax creates the step directory in the
calling thread, and orbax's own tracebacks of the failure are kept off the terminal
(``smjax.train.checkpoint_orbax``).

With several processes only process 0 touches the directory: the trainer gathers the
arrays to host numpy first, orbax runs on process 0 alone (its barriers limited to that
process), and on resume process 0 reads and broadcasts (``shared_meta``, the trainer's
``restore``). The files are the same as a single process writes, so either kind of run
resumes the other's checkpoints.
"""
from __future__ import annotations

import gc
import json
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any

import jax

from smjax.train import distributed as dist
from smjax.train import manifest as mf
from smjax.train.checkpoint_orbax import (checkpointer, first_line, flat_leaves, is_disk_full,
                                          quiet_orbax)
from smjax.train.outdir import probe_file
from smjax.core.files import atomic_write_text, fsync_dir

LATEST = "latest.json"
# the format of the checkpoints this smjax writes, and the only one it resumes: the arrays of
# ``smjax.train.state.TrainArrays`` by leaf position, the host state of
# ``TrainerState.to_json`` and a manifest of checksums in every step (``meta["format"]``; a
# checkpoint without the field is of format 1)
CHECKPOINT_FORMAT = 5


class CheckpointError(RuntimeError):
    """A checkpoint cannot be written or read; the message names the path and what to do."""


def checkpoint_dir(out_dir: str | Path) -> Path:
    return Path(out_dir) / "checkpoints"


def _write_failure(target: Path, root: Path, err: BaseException) -> str:
    kept = f"the previous checkpoint in {root} is kept"
    if is_disk_full(err):
        return (f"disk full: could not write checkpoint {target} ({first_line(err)}); {kept}; "
                f"free space, then --resume the run")
    return f"could not write checkpoint {target} ({first_line(err)}); {kept}"


def _check_writable(root: Path) -> None:
    """Fail fast and in one line: orbax's writer threads hang for minutes on a read-only
    directory before they give up."""
    try:
        root.mkdir(parents=True, exist_ok=True)
        probe_file(root / f".write-probe-{os.getpid()}")
    except OSError as err:
        raise CheckpointError(f"cannot write checkpoints to {root}: {err.strerror or err}; "
                              f"make it writable or choose another --out") from None


def _fresh_name(root: Path, step: int, in_force: str | None) -> str:
    """``step-N`` unless that exists (then a numbered variant): a re-save of the same
    chunk must never overwrite the checkpoint in force, nor the previous one kept."""
    name, k = f"step-{step}", 0
    while name == in_force or (root / name).exists():  # never over a kept step
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


def _prune(root: Path, keep: tuple) -> None:
    """Delete every step but ``keep`` and the temporaries of interrupted saves."""
    for old in root.iterdir():
        stale_step = old.name.startswith("step-") and old.name not in keep
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
    previous = _in_force(root)
    target = root / _fresh_name(root, step, previous)
    if target.exists():  # an unreferenced leftover of an interrupted save
        shutil.rmtree(target)
    failure = None
    before = set(threading.enumerate())
    try:
        writer = checkpointer()
        with quiet_orbax() as quiet:
            try:
                try:
                    writer.save(target, flat_leaves(arrays))
                    writer.wait_until_finished()
                finally:
                    writer.close()  # no writer thread outlives the save
            except Exception as err:  # disk full, read-only, I/O error
                quiet["failed"] = True
                failure = _write_failure(target, root, err)
            if failure is not None:  # (outside the except block, which holds the traceback)
                # the first failure ends the wait while other writer threads may still run
                # and report theirs: let them finish here, quietly, for a bounded time
                deadline = time.monotonic() + 10
                for thread in set(threading.enumerate()) - before:
                    thread.join(timeout=max(0.0, deadline - time.monotonic()))
                gc.collect()  # orbax's failed tasks are reported (to nobody) here, not at exit
        if failure is None:
            mf.write_manifest(target, step, meta)
            _fsync_tree(target)
            atomic_write_text(root / LATEST,
                              json.dumps({"step": step, "path": target.name, "meta": meta}))
    except Exception as err:
        failure = _write_failure(target, root, err)
    if failure is not None:  # the previous checkpoint stays in force
        if _in_force(root) != target.name:
            shutil.rmtree(target, ignore_errors=True)
        raise CheckpointError(failure)
    _prune(root, keep=(target.name, previous))
    return target


def load_meta(out_dir: str | Path, step: str | None = None, complete: bool = False) -> dict | None:
    """``latest.json``'s content, or ``step``'s (a step name: its manifest), or, without
    ``latest.json``, the newest step's with a readable manifest (None when there is
    none). With ``complete`` (a resume reads it) one of another format is refused first
    (``check_format``); a damaged one (a field of the wrong type; with ``complete``, also a
    field a resume needs that is missing) is refused in one line naming the file and field."""
    info, source = _find_meta(checkpoint_dir(out_dir), step)
    if info is not None and complete:
        check_format(out_dir, info)
    problem = None if info is None else mf.check_meta(info["meta"], complete)
    if problem is not None:
        raise CheckpointError(f"{source} is damaged: its field {problem!r} is missing or of the "
                              f"wrong type; resume another step with --resume-from STEP, or start "
                              f"again with --overwrite")
    return info


def _find_meta(root: Path, step: str | None) -> tuple[dict | None, Path]:
    """``load_meta``'s info before its fields are checked, and the file it came from."""
    latest = root / LATEST
    if step is not None:
        info = _from_manifest(root, step)
        return info, root / info["path"] / mf.MANIFEST
    if not latest.exists():
        for found in mf.steps_newest_first(root):
            info = _step_info(found)
            if info is not None:
                return info, found / mf.MANIFEST
        return None, latest
    fix = "restore it from a backup, resume a step with --resume-from STEP, or start again with --overwrite"
    try:
        info = json.loads(latest.read_text())
    except (OSError, ValueError) as err:
        raise CheckpointError(f"{latest} is unreadable or not valid JSON ({first_line(err)}); "
                              f"{fix}") from None
    # (the meta's own fields are checked by ``mf.check_meta``, which names the bad one)
    ok = (isinstance(info, dict) and isinstance(info.get("path"), str)
          and isinstance(info.get("meta"), dict))
    if not ok:
        raise CheckpointError(f"{latest} is not a smjax checkpoint index (missing path/meta); {fix}")
    if not (root / info["path"]).is_dir() or "/" in info["path"]:
        raise CheckpointError(f"{latest} points at {info['path']}, which does not exist; {fix}")
    manifest = mf.read_manifest(root / info["path"])
    if manifest is not None and manifest["meta"] != info["meta"]:
        raise CheckpointError(f"{latest} does not match the manifest of {info['path']} (it was "
                              f"edited or damaged); {fix}")
    return info, latest


def _step_info(step_dir: Path) -> dict | None:
    manifest = mf.read_manifest(step_dir)
    if manifest is None:
        return None
    return {"step": manifest["step"], "path": step_dir.name, "meta": manifest["meta"]}


def _from_manifest(root: Path, step: str) -> dict:
    name = step if str(step).startswith("step-") else f"step-{step}"
    info = _step_info(root / name) if "/" not in name and (root / name).is_dir() else None
    if info is None:
        kept = ", ".join(p.name for p in mf.steps_newest_first(root)) or "none"
        raise CheckpointError(f"no intact checkpoint step {name} in {root} (steps there: {kept})")
    return info


def verify_step(out_dir: str | Path, info: dict) -> None:
    """Refuse a step whose files differ from its manifest, naming it and what else is kept."""
    root = checkpoint_dir(out_dir)
    manifest = mf.read_manifest(root / info["path"])
    problem = ("its manifest is missing or unreadable" if manifest is None
               else mf.damage(root / info["path"], manifest))
    if problem is None:
        return
    others = [p.name for p in mf.steps_newest_first(root) if p.name != info["path"]]
    offer = (f"resume the previous step with --resume-from {others[0]}" if others else
             "no other step is kept: start again with --overwrite")
    raise CheckpointError(f"checkpoint {info['path']} in {root} is corrupt ({problem}); {offer}")


def shared_meta(out_dir: str | Path, step: str | None = None) -> dict | None:
    """``load_meta`` as a resume reads it (``complete``), as process 0 sees it, on every
    process (collective when several; its refusal is raised by every process alike)."""
    if not dist.is_multiprocess():
        return load_meta(out_dir, step, complete=True)
    info, error = None, None
    if dist.is_writer():
        try:
            info = load_meta(out_dir, step, complete=True)
        except CheckpointError as err:
            error = str(err)
    info, error = dist.broadcast_json([info, error])
    if error:
        raise CheckpointError(error)
    return info


def check_format(out_dir: str | Path, info: dict) -> None:
    """Refuse a checkpoint (``info``: ``load_meta``'s) of another format than
    ``CHECKPOINT_FORMAT``, naming its directory, its format and the one this smjax reads."""
    version = info["meta"].get("format", 1)
    if version == CHECKPOINT_FORMAT:
        return
    newer = type(version) is int and version > CHECKPOINT_FORMAT
    raise CheckpointError(
        f"checkpoint {info['path']} in {checkpoint_dir(out_dir)} is of format {version!r}, "
        f"written by {'a newer' if newer else 'an older'} smjax; this smjax resumes format "
        f"{CHECKPOINT_FORMAT} only: resume it with the smjax version that wrote it, or train "
        f"again in another directory")


def load_arrays(out_dir: str | Path, like: Any, step: str | None = None,
                verified: bool = False) -> Any:
    """The arrays of ``step`` (else the latest), shaped as ``like``; its files are checked
    against its manifest first unless the caller just did (``verified``)."""
    import orbax.checkpoint as ocp

    info = load_meta(out_dir, step)
    if info is None:
        raise FileNotFoundError(f"no checkpoint in {checkpoint_dir(out_dir)}")
    if not verified:
        verify_step(out_dir, info)
    if dist.is_multiprocess():
        # process 0 alone reads, into host numpy (``like`` holds numpy), then broadcasts
        abstract = flat_leaves(like)
    else:
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, flat_leaves(like))
    path = (checkpoint_dir(out_dir) / info["path"]).resolve()
    try:
        restored = checkpointer().restore(path, abstract)
    except Exception as err:  # truncated or corrupt data: orbax chains a long traceback
        said = str(err).lower()
        if "structure" in said and "match" in said:  # intact, but laid out by other code
            raise CheckpointError(
                f"checkpoint data in {path} holds other arrays than this smjax's trainer has "
                f"(another smjax version wrote it); resume it with the smjax version that "
                f"wrote it, or train again in another directory") from None
        raise CheckpointError(f"checkpoint data in {path} cannot be read ({first_line(err)}); "
                              f"it is truncated or corrupt: restore it or start again with "
                              f"--overwrite") from None
    leaves, treedef = jax.tree.flatten(like)
    return jax.tree.unflatten(
        treedef, [restored[str(i)] if x.size > 0 else x for i, x in enumerate(leaves)])
