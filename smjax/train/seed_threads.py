"""A run's seeds split into groups on a CPU, each group's program called from its own thread.

On one CPU device a training chunk or an episodes program runs its seeds one after another
(``lax.map``), and XLA:CPU runs a program's ops one at a time: the tick's small kernels
and the small matrix products of a learner's update keep about one core busy (a level
chunk of the quick start: 0.385 s on one core, 0.355 s on two). Two programs called from
two threads do run at once, so the seeds are dealt into as many groups as the process has
cores (at most one group per seed), the program is compiled once for a group's size, and
each call copies every group's rows out of the run's arrays, calls the program on each
group from its own thread and copies the results back in place: the same chunk of the
quick start takes 0.21 s instead of 0.28 s. A seed's numbers do not change: each group
runs the very loop body the whole batch would, on that seed's own inputs.

Seeds finish their levels at their own pace, so a call's seeds with work (``Busy``: a
chunk's active ones, a gate's due ones) are dealt evenly over the groups at each call; an
idle seed in a group costs next to nothing (a ``cond`` passes its state through).

Copying a chunk's rows out (every seed's learners and environments) costs as much as
joining them back, and most calls take the arrays the last call joined (a chunk's state)
or took (the policy bank) with the seeds dealt the same way. So each program keeps the
groups' arrays of its last call, filed under the whole array they belong to, and a call on
that very array with the same rows takes them instead of copying (``SeedGroups.split``).
Arrays are immutable, so a kept part always holds its rows of the whole it is filed under;
one that a call donated is copied anew.

Only where seeds run one after another on one CPU device of one process (elsewhere they
run side by side, ``vmap``, already). ``SMJAX_SEED_THREADS`` sets the number of threads
(``1``: one program for every seed, as before); unset, the cores this process may use.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import jax
import numpy as np

ALL_SEED_AXES = None  # every argument of the program has a leading seed axis


def thread_count(one_after_another: bool) -> int:
    """Threads a program's seed groups may run on: ``SMJAX_SEED_THREADS`` where set, else
    the cores this process may use; 1 where seeds do not run one after another on one CPU
    device of one process."""
    if not one_after_another or jax.process_count() > 1:
        return 1
    given = os.environ.get("SMJAX_SEED_THREADS", "").strip()
    if given:
        try:
            count = int(given)
        except ValueError:
            raise ValueError(f"SMJAX_SEED_THREADS must be a whole number, got {given!r}") from None
        if count < 1:
            raise ValueError(f"SMJAX_SEED_THREADS must be at least 1, got {count}")
        return count
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    return len(cores) if cores else (os.cpu_count() or 1)


def group_size(threads: int, seeds: int) -> int:
    """Seeds in each group of ``seeds`` on ``threads`` (a grouped program's seed axis)."""
    return -(-seeds // max(1, threads))


def group_count(threads: int, seeds: int) -> int:
    """Groups of ``seeds`` on ``threads``: as many as the threads, but none of copies alone
    (10 seeds on 8 threads are 5 groups of 2)."""
    return -(-seeds // group_size(threads, seeds))


class Busy(NamedTuple):
    """Which seeds of a call have work: those whose per-seed bool argument at ``position``
    equals ``when``. ``droppable``: an idle seed's results are meaningless (an episodes
    program's seeds not due), so a group of idle seeds alone is not run and its results
    are zeros; otherwise (a chunk's idle seeds keep their state) every group runs."""
    position: int
    when: bool
    droppable: bool


class SeedGroups:
    """``seeds`` seeds dealt into ``groups`` groups of ``size`` (``groups * size - seeds``
    padding rows, whose results are dropped). ``axes``: per argument, 0 (a leading seed
    axis) or None (shared by every seed); None: all 0. ``busy``: which seeds of a call have
    work (``Busy``); each call deals them evenly over the groups, so that no thread waits on
    another holding more of them (seeds finish their levels at their own pace)."""

    def __init__(self, seeds: int, groups: int, axes: tuple | None = ALL_SEED_AXES,
                 busy: Busy | None = None):
        self.seeds, self.groups, self.axes, self.busy = seeds, groups, axes, busy
        self.size = -(-seeds // groups)
        self._pool = ThreadPoolExecutor(groups - 1, thread_name_prefix="smjax-seed-group")
        self._kept: dict[int, _Kept] = {}  # the last call's groups' arrays, by id of the whole

    @classmethod
    def for_program(cls, threads: int, args: tuple, axes: tuple | None = ALL_SEED_AXES,
                    busy: Busy | None = None):
        """The groups for a program's ``args`` (arrays or shapes), or None where one program
        over every seed runs as well (one thread, or one seed)."""
        seeds, weak = _seed_count(args, axes)
        groups = group_count(threads, seeds)
        # a weakly typed input would come back strongly typed from the host copy
        return cls(seeds, groups, axes, busy) if groups > 1 and not weak else None

    def _per_seed(self, args: tuple) -> list[bool]:
        return [True] * len(args) if self.axes is None else [a == 0 for a in self.axes]

    def shapes(self, args: tuple) -> tuple:
        """A group's arguments: ``args``' shapes with ``size`` rows on the seed axis."""
        def group(x):
            return jax.ShapeDtypeStruct((self.size,) + tuple(x.shape[1:]), x.dtype,
                                        sharding=getattr(x, "sharding", None),
                                        weak_type=getattr(x, "weak_type", False))
        return tuple(jax.tree.map(group, a) if on else a
                     for a, on in zip(args, self._per_seed(args)))

    def deal(self, args: tuple) -> tuple[list[np.ndarray], list[bool]]:
        """Each group's rows for a call on ``args``, and whether it holds a busy seed. The
        busy seeds come first and are dealt in turn, so group sizes in busy seeds differ
        by one at most; padding repeats an idle seed where there is one (it costs nothing),
        else the last seed."""
        if self.busy is None:
            busy = np.ones(self.seeds, bool)
        else:
            busy = np.asarray(args[self.busy.position]) == self.busy.when
        idle = np.flatnonzero(~busy)
        order = np.concatenate([np.flatnonzero(busy), idle])
        pad = idle[-1] if len(idle) else self.seeds - 1
        order = np.concatenate([order, np.full(self.groups * self.size - self.seeds, pad)])
        rows = [order[g::self.groups] for g in range(self.groups)]
        return rows, [bool(busy[r].any()) for r in rows]

    def split(self, args: tuple, rows: list[np.ndarray], kept: dict | None = None
              ) -> list[tuple]:
        """These rows' arguments in arrays of their own: the groups' arrays of the last call
        where an argument is the array they were cut from or joined into (with the same
        rows), else copies (one transfer a group). ``kept``: files each argument's groups'
        arrays there, by the whole's id, for the next call."""
        on = self._per_seed(args)
        leaves, tree = jax.tree.flatten(tuple(a for a, o in zip(args, on) if o))
        key = _rows_key(rows)
        parts, seen = [], set()
        for x in leaves:  # a repeated array is copied for its second place (donation)
            parts.append(None if id(x) in seen else self._reuse(x, key))
            seen.add(id(x))
        copy = [i for i, p in enumerate(parts) if p is None]
        host = [np.asarray(leaves[i]) for i in copy]
        moved = [jax.device_put([h[take] for h in host]) for take in rows]
        for n, i in enumerate(copy):
            parts[i] = [group[n] for group in moved]
        if kept is not None:
            _file(kept, leaves, parts, key)
        out = []
        for g in range(len(rows)):
            group = iter(jax.tree.unflatten(tree, [p[g] for p in parts]))
            out.append(tuple(next(group) if o else a for a, o in zip(args, on)))
        return out

    def _reuse(self, x, key: bytes) -> list | None:
        """The last call's groups' arrays of ``x`` for rows ``key``, or None."""
        kept = self._kept.get(id(x))  # held, the whole's id names it alone
        if kept is None or kept.rows != key or any(p.is_deleted() for p in kept.parts):
            return None
        return kept.parts

    def join(self, rows: list[np.ndarray], results: list, kept: dict | None = None):
        """One result over the seeds from the groups' (``results[g]``: group ``g``'s, with a
        leading axis in ``rows[g]``'s order; None: not run, zeros). ``kept``: files the
        groups' arrays there, by the joined array's id, where every group ran."""
        first = next(r for r in results if r is not None)
        groups = [None if r is None else jax.tree.leaves(r) for r in results]
        flat = [None if g is None else [np.asarray(x) for x in g] for g in groups]
        ran = next(f for f in flat if f is not None)  # the leaves' shapes, for the zeros
        # where each seed's row lies in the groups' rows laid end to end (its first copy)
        _, where = np.unique(np.concatenate(rows), return_index=True)
        joined = jax.device_put([
            np.concatenate([np.zeros_like(x) if f is None else f[i] for f in flat])[where]
            for i, x in enumerate(ran)])
        if kept is not None and all(g is not None for g in groups):
            _file(kept, joined, [list(p) for p in zip(*groups)], _rows_key(rows))
        return jax.tree.unflatten(jax.tree.structure(first), joined)

    def program(self, compiled) -> "GroupedProgram":
        """``compiled`` (a program over one group) called over every seed."""
        return GroupedProgram(self, compiled)

    def run(self, compiled, args: tuple):
        """``compiled`` on every group (but a droppable group of idle seeds alone), the first
        on this thread, the others on the pool."""
        rows, has_busy = self.deal(args)
        due = [g for g in range(self.groups)
               if has_busy[g] or not (self.busy and self.busy.droppable)] or [0]
        kept: dict[int, _Kept] = {}  # filed by split and join, for the next call
        groups = self.split(args, [rows[g] for g in due], kept)
        others = [self._pool.submit(_ready, compiled, g) for g in groups[1:]]
        ran = dict(zip(due, [_ready(compiled, groups[0])] + [f.result() for f in others]))
        out = self.join(rows, [ran.get(g) for g in range(self.groups)], kept)
        self._kept = kept
        return out


class GroupedProgram:
    """A program compiled for one group of seeds, called with every seed's arguments."""

    def __init__(self, groups: SeedGroups, compiled):
        self.groups, self.compiled = groups, compiled

    def __call__(self, *args):
        return self.groups.run(self.compiled, args)


class _Kept(NamedTuple):
    """A whole array's rows in the groups of a call: ``parts[g]``, group g's (``rows``:
    the call's rows, ``_rows_key``). ``whole`` is held so that its id names it alone."""
    whole: jax.Array
    rows: bytes
    parts: list


def _rows_key(rows: list[np.ndarray]) -> bytes:
    return np.asarray(rows, np.int64).tobytes()


def _file(kept: dict, wholes: list, parts: list[list], key: bytes) -> None:
    """Files each of ``wholes`` (immutable arrays only) with its groups' ``parts``."""
    for whole, own in zip(wholes, parts):
        if isinstance(whole, jax.Array):
            kept[id(whole)] = _Kept(whole, key, own)


def _ready(compiled, args: tuple):
    return jax.block_until_ready(compiled(*args))


def _seed_count(args: tuple, axes: tuple | None) -> tuple[int, bool]:
    """The seeds of a program's arguments, and whether one of their per-seed arrays is
    weakly typed."""
    per_seed = args if axes is None else [a for a, axis in zip(args, axes) if axis == 0]
    leaves = jax.tree.leaves(per_seed)
    if not leaves:
        return 1, False
    return int(leaves[0].shape[0]), any(getattr(x, "weak_type", False) for x in leaves)
