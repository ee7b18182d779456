"""Calls of the episodes program (a gate, fine-tuning's checks, the evaluation), each size
compiled once, and a few due seeds of many run as a smaller batch.

Where seeds run side by side (a GPU), the episodes program ticks every seed, skipped ones
included, for as long as the slowest due seed needs: a gate that concerns 3 seeds of 100
costs what all 100 cost. There the due seeds are gathered into a batch of ``bucket`` seeds
(padded with skipped ones), the program runs at that size, and each result goes back to
its seed's place. One extra size, not one per count of due seeds: each size is a compile
of its own (compiled ahead with the full one). A seed's episodes do not depend on the
seeds beside it, so its result is the same, up to the order of float sums a device picks
for another batch size. Only on one device: seeds sharded over several would first have
to move between them.
"""
from __future__ import annotations

import functools
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.options.episodes import SEED_AXES, SKIP
from smjax.train.ahead import CompileAhead, placed, resolve, signature

# A batch this small costs about what one seed costs on a GPU: the episodes program is
# bound by its per-tick launches up to ~30 seeds (a gate attempt on one H100: 0.129 s for
# 10 seeds, 0.212 s for 30, 0.551 s for 100)
BUCKET = 16


class EpisodeCalls:
    """The episodes program's calls: ``compile_fn(args, num_envs)`` compiles it for one
    argument layout; ``side_by_side``: the seeds run in one vmapped program (one after
    another, a skipped seed already costs nothing); ``bucket``: the smaller batch's size."""

    def __init__(self, compile_fn: Callable[[tuple, int], Any], side_by_side: bool,
                 bucket: int = BUCKET):
        self.compile_fn, self.bucket = compile_fn, bucket
        self.on = side_by_side and jax.device_count() == 1
        self.compiled: dict[tuple, Any] = {}

    def __call__(self, args: tuple, num_envs: int) -> tuple[dict, float]:
        """The program's result on ``args`` and the seconds this call spent compiling it or
        waiting for its compile."""
        rows = self.rows(args)
        if rows is None:
            return self._call(args, num_envs)
        result, compile_s = self._call(gather(args, rows), num_envs)
        return scatter(result, rows, args[SKIP].shape[0]), compile_s

    def _call(self, args: tuple, num_envs: int) -> tuple[dict, float]:
        key = (num_envs, signature(args))
        program, compile_s = resolve(self.compiled.get(key), args,
                                     lambda xs: self.compile_fn(xs, num_envs))
        self.compiled[key] = program
        return program(*args), compile_s

    def ahead(self, args: tuple, num_envs: int, ahead: CompileAhead) -> None:
        """Compile the program for these arguments (arrays or shapes), and its smaller
        batch where one may run, on ``ahead``'s thread, unless compiled or under way."""
        every = [args] + ([self.small_shapes(args)] if self.applies(args[SKIP].shape[0]) else [])
        for each in every:
            key = (num_envs, signature(each))
            if key not in self.compiled and ahead.on:
                self.compiled[key] = ahead.submit(
                    f"episodes-{num_envs}", lambda xs: self.compile_fn(xs, num_envs), each)

    def applies(self, num_seeds: int) -> bool:
        """Whether a few of this many seeds may run as the smaller batch: at least twice
        the bucket, or it would save little."""
        return self.on and num_seeds >= 2 * self.bucket

    def rows(self, args: tuple) -> np.ndarray | None:
        """int [bucket]: the due seeds of ``args``, then the seed count (no seed) for the
        rest; None where the whole batch runs (too many due, or none)."""
        num_seeds = args[SKIP].shape[0]
        if not self.applies(num_seeds):
            return None
        due = np.flatnonzero(~np.asarray(jax.device_get(args[SKIP])))
        if not 0 < due.size <= self.bucket:
            return None
        rows = np.full((self.bucket,), num_seeds, np.int32)
        rows[:due.size] = due
        return rows

    def small_shapes(self, args: tuple) -> tuple:
        """The smaller batch's arguments (shapes, laid out as ``args``')."""
        small = jax.eval_shape(gather, args, jax.ShapeDtypeStruct((self.bucket,), jnp.int32))
        return placed(small, getattr(jax.tree.leaves(args)[0], "sharding", None))


@jax.jit
def gather(args: tuple, rows: jax.Array) -> tuple:
    """The episodes arguments of the seeds at ``rows`` (a row past the seeds: the last
    seed's inputs, skipped)."""
    num_seeds = args[SKIP].shape[0]
    clipped = jnp.minimum(rows, num_seeds - 1)
    out = [x if axis is None else jax.tree.map(lambda v: v[clipped], x)
           for x, axis in zip(args, SEED_AXES)]
    out[SKIP] = out[SKIP] | (rows >= num_seeds)
    return tuple(out)


@functools.partial(jax.jit, static_argnums=(2,))
def scatter(result: dict, rows: jax.Array, num_seeds: int) -> dict:
    """The smaller batch's ``result`` at its seeds' places of a batch of ``num_seeds``
    (zeros elsewhere: a skipped seed's result is meaningless)."""
    return jax.tree.map(lambda r: jnp.zeros((num_seeds,) + r.shape[1:], r.dtype)
                        .at[rows].set(r, mode="drop"), result)
