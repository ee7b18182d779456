"""The output directory of a run: validated before anything compiles, locked while it runs.

``prepare_out_dir`` checks that ``--out`` can hold a run (not a file, creatable,
writable) and takes an advisory lock on it (``.smjax.lock`` with the owner's pid, host
and start time). The lock is an ``flock`` on that file, so the kernel releases it when
the owner exits in any way (SIGKILL included); a lock file whose lock is free is
therefore stale, and a warning names it when a new run takes it over. A directory that already
holds a run's files (results, curves, policy, checkpoints) is refused unless the caller resumes
it or asks to overwrite it, so nothing is replaced without a word; ``--overwrite`` then
deletes exactly the files the refusal named (inside ``checkpoints``, only smjax's own).

Nothing is written or deleted through a symbolic link: a run file, the lock or a probe
that is a link is refused (a planted link would otherwise redirect a write, or a delete,
outside ``--out``), and the lock and probe files are created with ``O_NOFOLLOW``.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import shutil
import socket
import stat
import time
import warnings
from pathlib import Path

LOCK_NAME = ".smjax.lock"
# what a run writes into its directory; --overwrite deletes those of them found
RUN_FILES = ("results.json", "curves.csv", "curves.png", "policy", "checkpoints",
             "tensorboard", "sweep.json", "profile.json")


class OutDirError(ValueError):
    """The output directory cannot be used; the message names it and says what to do."""


class RunExistsError(OutDirError, FileExistsError):
    """The directory holds a run that is neither resumed nor to be overwritten."""


class NothingToResumeError(OutDirError, FileNotFoundError):
    """``--resume`` of a directory that does not exist."""


# bytes of one file or folder name (ext4, APFS, NTFS, ...; ``pathconf`` needs the folder
# to exist, and a name too long makes every other check fail with ENAMETOOLONG)
NAME_MAX = 255


def check_path_names(flag: str, path: str | Path) -> None:
    """Refuse a path with a name longer than ``NAME_MAX`` bytes, naming the flag."""
    for part in Path(path).parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            shown = part if len(part) <= 40 else f"{part[:40]}..."
            raise OutDirError(f"{flag}: the name {shown!r} is {size} bytes long; a file or "
                              f"folder name is at most {NAME_MAX} bytes")


def check_out_dir(out: Path) -> None:
    """Refuse a path that can never hold a run: empty, a file, uncreatable, not writable."""
    if not str(out).strip():
        raise OutDirError("--out is empty (an unset shell variable?); name a directory")
    check_path_names("--out", out)
    try:
        if out.exists() and not out.is_dir():
            raise OutDirError(f"--out {out} is a file, not a directory; choose a directory")
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutDirError(f"--out {str(out)[:200]} cannot be created ({err.strerror or err}); "
                          f"choose a writable location") from None
    try:
        probe_file(out / f".smjax-write-probe-{os.getpid()}")
    except OSError as err:
        raise OutDirError(f"--out {out} is not writable ({err.strerror or err}); fix its "
                          f"permissions or choose another directory") from None


def probe_file(path: Path) -> None:
    """Create and remove an empty file at ``path``, never through a planted link."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
    os.close(fd)
    os.unlink(path)


def check_no_links(out: Path) -> None:
    """Refuse run files (and the checkpoints' entries) that are symbolic links: the run
    would write, or ``--overwrite`` delete, wherever they lead."""
    names = [LOCK_NAME] + _run_names(out)
    if (out / "checkpoints").is_dir() and not (out / "checkpoints").is_symlink():
        names += [f"checkpoints/{c.name}" for c in (out / "checkpoints").iterdir()]
    for name in names:
        if (out / name).is_symlink():
            raise OutDirError(f"{out / name} is a symbolic link; a run never writes or deletes "
                              f"through links: remove it, or choose another --out")


def _holds_checkpoint(folder: Path) -> bool:
    """A checkpoints folder with anything resumable: latest.json or a complete step (an
    orbax temporary of a save killed before the first checkpoint holds nothing)."""
    return any(c.name == "latest.json" or (c.name.startswith("step-")
                                           and ".orbax-checkpoint-tmp" not in c.name)
               for c in folder.iterdir())


def _run_names(out: Path) -> list[str]:
    """RUN_FILES plus a sweep's ``point-<k>`` folders (those holding a results.json)."""
    points = sorted(p.name for p in out.glob("point-*")
                    if p.name[6:].isdigit() and (p.is_symlink() or (p / "results.json").is_file()))
    return list(RUN_FILES) + points


def existing_run_files(out: Path) -> list[str]:
    """The run files ``out`` holds (a checkpoints folder only when it holds a checkpoint)."""
    found = []
    for name in _run_names(out):
        p = out / name
        if name == "checkpoints" and p.is_dir():
            if _holds_checkpoint(p):
                found.append(name)
        elif p.is_file() or (p.is_dir() and any(p.iterdir())):
            found.append(name)
    return found


def _smjax_checkpoint_entry(name: str) -> bool:
    """What ``smjax.train.checkpoint`` writes into ``checkpoints``."""
    return (name == "latest.json" or name.startswith(("step-", ".latest.json.", ".write-probe-"))
            or ".orbax-checkpoint-tmp" in name)


def clear_run_files(out: Path, found: list[str]) -> None:
    """``--overwrite``: remove the run files the refusal named (``found``), nothing else;
    in ``checkpoints`` only smjax's own entries (another tool's files there stay)."""
    for name in found:
        p = out / name
        if p.is_symlink():  # (check_no_links refuses these first)
            raise OutDirError(f"{p} is a symbolic link; remove it yourself")
        if name == "checkpoints":
            for entry in p.iterdir():
                if _smjax_checkpoint_entry(entry.name):
                    _remove(entry)
            with contextlib.suppress(OSError):
                p.rmdir()  # only if nothing else is left in it
        else:
            _remove(p)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    else:
        p.unlink(missing_ok=True)


class DirLock:
    """An advisory, kernel-released lock on ``out`` for the life of a run."""

    def __init__(self, out: Path):
        self.path = Path(out) / LOCK_NAME
        self.fd: int | None = None
        self.stale_owner: dict | None = None  # the owner of a stale lock taken over

    def acquire(self) -> "DirLock":
        while True:
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as err:
                os.close(fd)
                if err.errno in (errno.EAGAIN, errno.EACCES):
                    raise OutDirError(self._held_message()) from None
                raise
            # the file may have been unlinked by its releasing owner between open and flock
            if _same_file(fd, self.path):
                break
            os.close(fd)
        self.stale_owner = _read_owner(fd)
        _write_owner(fd)
        self.fd = fd
        return self

    def _open(self) -> int:
        """The lock file, created exclusively, or (a stale one) opened; never a link, a
        FIFO or anything but a regular file."""
        try:
            return os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        except FileExistsError:
            pass
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK)
        except FileNotFoundError:  # released between the two opens: create it afresh
            return self._open()
        except OSError as err:
            if err.errno == errno.ELOOP:
                raise OutDirError(f"{self.path} is a symbolic link, not a smjax lock; remove it "
                                  f"(a run never writes through links)") from None
            raise OutDirError(f"{self.path} cannot be opened ({err.strerror or err}); remove "
                              f"it") from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise OutDirError(f"{self.path} is not a regular file, not a smjax lock; remove it")
        return fd

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)  # unlink first: a waiter then re-opens anew
        finally:
            os.close(self.fd)
            self.fd = None

    def _held_message(self) -> str:
        try:
            owner = json.loads(self.path.read_text())
            who = f"pid {owner.get('pid')} on host {owner.get('host')}, started {owner.get('started')}"
        except (OSError, ValueError, AttributeError):
            who = "another process"
        return (f"--out {self.path.parent} is in use by a running smjax run ({who}); wait for it "
                f"to finish or choose another directory")

    def __enter__(self) -> "DirLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.fstat(fd).st_ino == os.stat(path).st_ino
    except FileNotFoundError:
        return False


def _read_owner(fd: int) -> dict | None:
    try:
        data = os.pread(fd, 4096, 0)
        return json.loads(data) if data.strip() else None
    except (OSError, ValueError):
        return {"pid": "?", "host": "?"}


def _write_owner(fd: int) -> None:
    owner = {"pid": os.getpid(), "host": socket.gethostname(),
             "started": time.strftime("%Y-%m-%dT%H:%M:%S")}
    os.ftruncate(fd, 0)
    os.pwrite(fd, json.dumps(owner).encode(), 0)
    os.fsync(fd)


def prepare_out_dir(out: str | Path, *, resume: bool, overwrite: bool) -> DirLock:
    """Validate ``out``, lock it and, with ``overwrite``, clear the previous run's files.

    Returns the held lock (release it when the run ends). Raises ``OutDirError`` when
    the directory is unusable, locked by a live run, or holds a run that is neither
    resumed nor to be overwritten.
    """
    if not str(out).strip():
        raise OutDirError("--out is empty (an unset shell variable?); name a directory")
    out = Path(out)
    if resume and overwrite:
        raise OutDirError("--resume and --overwrite contradict each other; pass one of them")
    if resume and not out.is_dir():
        raise NothingToResumeError(f"nothing to resume: {out} is not a directory (train with "
                                   f"--out {out} first)")
    check_out_dir(out)
    lock = DirLock(out).acquire()
    try:
        if lock.stale_owner:
            o = lock.stale_owner
            warnings.warn(f"took over the stale lock of {out} (pid {o.get('pid')} on host "
                          f"{o.get('host')} is gone)", stacklevel=2)
        check_no_links(out)
        found = existing_run_files(out)
        if found and not resume:
            if not overwrite:
                raise RunExistsError(
                    f"{out} already holds a run ({', '.join(found)}); pass --resume to continue "
                    f"it, --overwrite to replace it, or choose another output directory")
            clear_run_files(out, found)
    except BaseException:
        lock.release()
        raise
    return lock
