"""Which exceptions are a user's mistake, and the one line the CLI prints for each.

A user error (a bad flag, config, path, checkpoint, resume mismatch, a non-finite run, a
batch that does not fit) exits with code 2 and one or two lines naming the file, field
or value; ``--debug`` re-raises it so the traceback shows. Anything else is a bug: one
line, exit code 1, and the hint to rerun with ``--debug``.
"""
from __future__ import annotations

import errno
import re

USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, KeyError, TypeError,
                                                FileNotFoundError, FileExistsError,
                                                IsADirectoryError, NotADirectoryError,
                                                PermissionError, FloatingPointError)


class UsageError(ValueError):
    """A flag or flag combination the CLI refuses; the message says what to do."""


def _first_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[0] if lines else ""


# XLA's words for an allocation that failed: a device's RESOURCE_EXHAUSTED (with
# "memory"), and the CPU client's INTERNAL "Out of memory allocating N bytes." or
# "Failed to allocate ..." (a host out of memory is not RESOURCE_EXHAUSTED there)
_OOM_WORDS = re.compile(r"out of memory|failed to allocate (memory|buffer|\d)", re.IGNORECASE)


def is_out_of_memory(err: BaseException) -> bool:
    """XLA's out-of-memory error on a device or the CPU, or Python's. (A full disk is
    RESOURCE_EXHAUSTED too, in the I/O library's words; it is not this.)"""
    from smjax.train.checkpoint import CheckpointError

    if isinstance(err, MemoryError):
        return True
    if isinstance(err, CheckpointError):
        return False
    text = str(err)
    return ("RESOURCE_EXHAUSTED" in text and "memory" in text.lower()) or bool(
        _OOM_WORDS.search(text))


def user_message(err: BaseException, batch: str | None = None) -> str | None:
    """The one line for a user error, else None (a bug)."""
    from smjax.train.checkpoint import CheckpointError
    from smjax.train.results import ResultsError

    if is_out_of_memory(err):
        what, advice = (f" with {batch}", "lower one of these") if batch else (
            "", "lower --num-envs or --seeds")
        return f"out of memory{what} ({_first_line(str(err))[:200]}); {advice}"
    if isinstance(err, OSError) and err.errno == errno.ENOSPC:
        return f"disk full writing {err.filename or 'output'}; free space and --resume the run"
    if isinstance(err, CheckpointError):
        return _first_line(str(err))
    if isinstance(err, ResultsError):  # says how to write the results from the checkpoint
        return str(err)
    if isinstance(err, KeyError) and err.args:
        return str(err.args[0])  # str(KeyError) would quote the message
    if isinstance(err, USER_ERRORS):
        text = _first_line(str(err)) or type(err).__name__
        if isinstance(err, OSError) and err.filename and str(err.filename) not in text:
            text = f"{err.filename}: {text}"
        return text
    return None
