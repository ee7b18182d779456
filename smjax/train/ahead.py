"""Programs a run needs later, compiled on a thread while its first programs train.

A run's largest program, its level chunk, takes longer to compile than everything the run
does before its first chunk (the engine's and the trainer's small programs: resets, learner
inits, copies); the gate's episodes program, joint fine-tuning's chunk and the final
evaluation's program are needed seconds or minutes later, and compiling each where it is
first needed stops training for as long. ``CompileAhead`` compiles them on background
threads instead (``for_backend``). All four are submitted as soon as the trainer knows
its state's shapes (before it builds them), the level chunk first, so its compile runs
beside the small programs that the main thread traces, compiles and runs meanwhile. With
a GPU (or another accelerator) three compile at a time: the host's cores are otherwise idle
while the device trains. On a CPU one thread compiles them one after another: XLA's
compile and the training chunks already keep a CPU's cores busy, so a second compile
thread makes a run slower, while one, started before the main thread's small programs,
makes it faster than compiling the level chunk where it first runs. They are the very
programs the run would compile when first needed (same function, shapes, dtypes and
layout), so results do not change; where one is needed before its compile has finished,
the run waits for it, and that wait is its compile time.

On by default with one process (several processes keep compiling where needed, in the
same order on each); ``SMJAX_COMPILE_AHEAD=0`` turns it off.
"""
from __future__ import annotations

import os
import queue
import threading
import weakref
from concurrent.futures import CancelledError, Future
from typing import Any, Callable, NamedTuple

import jax

from smjax.core.timeline import TIMELINE


def signature(args) -> tuple:
    """What a compiled program fixes of its arguments: their structure and each array's
    shape, dtype, layout and weak type, or a Python value's type (a call that differs
    needs its own compile)."""
    leaves, tree = jax.tree.flatten(args)
    return (tree,) + tuple((getattr(x, "shape", None), getattr(x, "dtype", type(x)),
                            getattr(x, "sharding", None), getattr(x, "weak_type", None))
                           for x in leaves)


def abstract(tree):
    """``tree`` with every array replaced by its shape, dtype, layout and weak type: what a
    compile needs, without holding buffers a later call may donate."""
    def one(x):
        if isinstance(x, jax.Array):
            return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding,
                                        weak_type=x.weak_type)
        return x
    return jax.tree.map(one, tree)


def placed(shapes, sharding):
    """``shapes`` (``jax.eval_shape``'s) laid out by ``sharding``: the arguments of a program
    compiled before the arrays it will run on exist."""
    return jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding,
                                                       weak_type=x.weak_type), shapes)


def arguments(make: Callable[[Any], Any], state):
    """``make(state)``: a program's arguments from the run's state; where ``state`` holds
    only shapes (``placed``), their shapes, from tracing ``make`` (nothing runs)."""
    leaves = jax.tree.leaves(state)
    if not leaves or not isinstance(leaves[0], jax.ShapeDtypeStruct):
        return make(state)
    return placed(jax.eval_shape(make, state), leaves[0].sharding)


class Pending(NamedTuple):
    """A program being compiled ahead for arguments of this ``signature``."""
    future: Future
    signature: tuple


class CompileAhead:
    """Background threads that compile programs, in the order submitted.

    ``threads``: how many programs compile at once. A thread ends when nothing is left to
    compile, so an ahead that is never closed keeps no thread waiting. A run that stops
    early (an error, Ctrl-C) cancels the compiles not yet started; a thread cannot be
    stopped inside XLA's compile, so the interpreter waits for those under way before it
    exits (a daemon thread left running while it shuts down aborts the process). The
    ``smjax`` command does not wait: it exits at once (``compiling``)."""

    def __init__(self, threads: int = 1, enabled: bool | None = None, from_start: bool = False):
        """``from_start``: the trainer submits its level chunk as soon as it knows the
        shapes, to compile beside its small programs (otherwise, or where the trainer
        cannot, the level chunk compiles where it first runs, and the rest beside it or
        after it: ``beside_main``)."""
        if enabled is None:
            enabled = (os.environ.get("SMJAX_COMPILE_AHEAD", "1").strip().lower()
                       not in ("0", "false", "off", "no") and jax.process_count() == 1)
        self.on, self.threads, self.from_start = bool(enabled), threads, from_start
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._workers = self._busy = 0  # threads alive; compiles under way
        _LIVE.add(self)

    @classmethod
    def for_backend(cls) -> "CompileAhead":
        """From the start: on a CPU one thread (its cores compile and train), beside an
        accelerator three (the level chunk, then the gate's and joint fine-tuning's
        programs at once)."""
        return cls(1 if jax.default_backend() == "cpu" else 3, from_start=True)

    @property
    def beside_main(self) -> bool:
        """Whether programs compile here while the main thread compiles its own (a level
        chunk not compiled ahead): with threads to spare (an accelerator's host). One
        thread (a CPU's) waits until the main thread's compile is done: the two would
        share the cores the chunks train on."""
        return self.threads > 1

    def submit(self, label: str, compile_fn: Callable[[Any], Any], args) -> Pending | None:
        """``compile_fn(abstract(args))`` on a thread (None where compiling ahead is off);
        its seconds go on the timeline, beside the phases, as ``compile ahead (a thread):
        label``."""
        if not self.on:
            return None
        future: Future = Future()
        with self._lock:
            self._queue.put((future, label, compile_fn, abstract(args)))
            if self._workers < self.threads:
                self._workers += 1
                threading.Thread(target=self._work, name="smjax-compile-ahead").start()
        return Pending(future, signature(args))

    def _next(self):
        """The next program to compile, or None (the thread ends: nothing is queued)."""
        with self._lock:
            try:
                return self._queue.get_nowait()
            except queue.Empty:
                self._workers -= 1
                return None

    def _work(self) -> None:
        while (item := self._next()) is not None:
            future, label, compile_fn, shapes = item
            if not future.set_running_or_notify_cancel():
                continue
            began = TIMELINE.now()
            with self._lock:
                self._busy += 1
            try:
                future.set_result(compile_fn(shapes))
            except BaseException as error:  # noqa: BLE001 - raised again where it is used
                future.set_exception(error)
            finally:
                with self._lock:
                    self._busy -= 1
            TIMELINE.inside(f"compile ahead (a thread): {label}", TIMELINE.now() - began)

    def close(self) -> None:
        """Cancel what has not started; the threads end after the compiles under way."""
        self.on = False
        with self._lock:
            while True:
                try:
                    self._queue.get_nowait()[0].cancel()
                except queue.Empty:
                    break


_LIVE: "weakref.WeakSet[CompileAhead]" = weakref.WeakSet()


def compiling() -> bool:
    """Whether a compile ahead is under way (for a command that is about to exit)."""
    return any(ahead._busy for ahead in list(_LIVE))


def resolve(entry, args, compile_fn: Callable[[Any], Any]) -> tuple[Any, float]:
    """The program to call on ``args``, from ``entry`` (a compiled program, a ``Pending``
    one, or None), and the seconds this call spent compiling it or waiting for it. A
    compile ahead for other arguments, or one that failed or was cancelled, is done again
    here (``compile_fn(args)``), so an error is raised where the program is used."""
    if entry is not None and not isinstance(entry, Pending):
        return entry, 0.0
    began, program = TIMELINE.now(), None
    if entry is not None and entry.signature == signature(args):
        try:
            program = entry.future.result()
        except (Exception, CancelledError):  # compiled again below, raising where used
            program = None
    if program is None:
        program = compile_fn(args)
    return program, TIMELINE.now() - began
