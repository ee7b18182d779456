"""What ``smjax.train.checkpoint`` needs of orbax: its checkpointer, the arrays' stored
layout, and a failed save kept to one line.

orbax writes from background threads. A failure there (read-only or full file system,
I/O error) makes it log every writer thread's traceback, its I/O library print more, and
asyncio report each failed future when it is garbage collected: hundreds of lines, often
after the save has already reported the failure. ``quiet_orbax`` holds all of that back
while a save runs (only the save's own threads': a save runs beside training);
``first_line`` and ``is_disk_full`` read the failure for the one line the caller raises.
"""
from __future__ import annotations

import contextlib
import errno
import io
import logging
import os
import sys
import threading
import traceback
from typing import Any

import jax

from smjax.train import distributed as dist


def flat_leaves(arrays: Any) -> dict:
    """Leaves by position, without zero-size ones (orbax refuses them; e.g. MJX's empty
    ``act``): restoring takes those from the template, where they are empty as well."""
    return {str(i): x for i, x in enumerate(jax.tree.leaves(arrays)) if x.size > 0}


def checkpointer():
    """An orbax ``StandardCheckpointer`` that fails at once and, with several processes,
    runs on process 0 alone."""
    import orbax.checkpoint as ocp

    kwargs = {}
    try:
        # The step directory is created in the calling thread, so a failure to create it
        # (read-only or full file system) raises at once: created in a background thread,
        # its failure would leave orbax's writer threads waiting minutes for the directory.
        kwargs["async_options"] = ocp.options.AsyncOptions(create_directories_asynchronously=False)
    except (AttributeError, TypeError):  # an orbax without the option
        pass
    if dist.is_multiprocess():
        # only process 0 calls orbax; without this its barriers would wait for the others
        kwargs["multiprocessing_options"] = ocp.options.MultiprocessingOptions(
            primary_host=0, active_processes={0})
    return ocp.StandardCheckpointer(**kwargs)


class _QuietOrbax(logging.Filter):
    """Drops orbax's log records (and asyncio's about orbax's tasks) while a save runs."""

    def filter(self, record: logging.LogRecord) -> bool:
        where = f"{os.sep}orbax{os.sep}"
        return where not in (record.pathname or "") and where not in record.getMessage()


class _OrbaxFutureNoise(logging.Filter):
    """asyncio's "exception was never retrieved" reports about the futures of a failed
    orbax save, which surface whenever they are garbage collected (often at exit, after
    the save has reported the failure): one per file, tens of tracebacks."""

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if record.exc_info and record.exc_info[2] is not None:
            text += "".join(traceback.format_tb(record.exc_info[2]))
        return "orbax" not in text


_FUTURE_NOISE = _OrbaxFutureNoise()


class _HeldForTheSave(io.TextIOBase):
    """``sys.stderr`` while a save runs: what the saving thread and the threads it starts
    (orbax's) write is held; every other thread's (training goes on while a checkpoint
    is written) passes straight through."""

    def __init__(self, through, held: io.StringIO):
        self.through, self.held = through, held
        self.others = set(threading.enumerate()) - {threading.current_thread()}

    def write(self, text: str) -> int:
        saving = threading.current_thread() not in self.others
        return (self.held if saving else self.through).write(text)

    def flush(self) -> None:
        self.through.flush()

    def __getattr__(self, name):  # encoding, isatty, fileno, ...: the real stream's
        return getattr(self.through, name)


@contextlib.contextmanager
def quiet_orbax():
    """A failed save makes orbax log every writer thread's traceback and its I/O library
    print more (hundreds of lines); the caller reports a failure itself, in one line.
    What the save prints on stderr is held back and passed on only if it succeeds (the
    caller sets ``state["failed"]``)."""
    loggers = [logging.getLogger(name) for name in ("absl", "asyncio", "")]
    quiet, held, state = _QuietOrbax(), io.StringIO(), {"failed": False}
    if _FUTURE_NOISE not in loggers[1].filters:  # for the life of the process
        loggers[1].addFilter(_FUTURE_NOISE)
    for logger in loggers:
        logger.addFilter(quiet)
    try:
        with contextlib.redirect_stderr(_HeldForTheSave(sys.stderr, held)):
            yield state
    except BaseException:
        state["failed"] = True
        raise
    finally:
        for logger in loggers:
            logger.removeFilter(quiet)
        if not state["failed"] and held.getvalue():
            sys.stderr.write(held.getvalue())


def is_disk_full(err: BaseException) -> bool:
    text = str(err)
    return ((isinstance(err, OSError) and err.errno == errno.ENOSPC) or "No space left" in text
            or ("RESOURCE_EXHAUSTED" in text and "writ" in text.lower()))


def first_line(err: BaseException) -> str:
    """The error's type and the first line of its message, cut to 300 characters."""
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0] if text else ''}"[:300]
