"""Running the compiled chunks for the driver loop (:mod:`smjax.train.loop`).

A chunk is ``updates_per_chunk`` learner updates for every seed at once, each at its own
stage: seeds at a level or in a fine-tuning turn run the level chunk (``Engine.chunk``:
the option trained, teleports and episode continuation are per-seed inputs), seeds in
joint fine-tuning run ``Engine.joint_chunk``. Each program is compiled once per run.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor, wait
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.train import distributed as dist
from smjax.train.ahead import CompileAhead, arguments, resolve
from smjax.train.engine import CHUNK_BUSY, ChunkControls
from smjax.train.seed_arrays import NonFiniteError, select_seeds
from smjax.train.slots import Slots
from smjax.train.stages import ChunkOut, SeedControls


class ChunkRunner:
    """Calls the engine's chunk programs on the slots' device state and keeps the result.
    ``metrics``: gather the learners' update metrics (a collective with several processes)."""

    def __init__(self, engine, slots: Slots, metrics: bool):
        self.engine, self.slots, self.metrics = engine, slots, metrics
        self.level_program = self.joint_program = None
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="smjax-joint-chunk")

    def run(self, controls: list[SeedControls], active: list[bool],
            joint_controls: tuple | None, chunk: int, describe: Callable[[], str]
            ) -> tuple[ChunkOut, float]:
        """Chunk number ``chunk``: the level chunk for the ``active`` seeds whose controls
        are not joint, joint fine-tuning's for those that are (``joint_controls``: its
        per-seed inputs); its outputs and the seconds spent compiling. Non-finite learner
        parameters raise ``NonFiniteError`` (``describe()``: where the seeds train).

        Where seeds run in groups on threads (a CPU), the two programs run at once, so that
        a core one leaves idle (a seed or two still at a level) serves the other. Each
        keeps its idle seeds' windows as they were, so each seed's come from the program it
        ran in: the same arrays as one program after the other."""
        joint = [s for s, (c, on) in enumerate(zip(controls, active)) if on and c.joint]
        level = [on and not c.joint for c, on in zip(controls, active)]
        a = self.slots.arrays
        where = f"chunk {chunk} (joint fine-tuning of seeds {[self.slots.seeds[s] for s in joint]})"
        tune = lambda a: self.joint(joint, *joint_controls, lambda: where, a)  # noqa: E731
        beside = (self._pool.submit(tune, a)
                  if any(level) and joint and self.engine.seed_threads > 1 else None)
        out, compile_s = None, 0.0
        if any(level):
            try:
                out, compile_s, fields = self.level(
                    controls, level, lambda: f"chunk {chunk} (training: {describe()})", a)
            finally:
                if beside is not None and not beside.done():
                    wait([beside])  # not left running on arrays the caller may discard
            a = a.replace(**fields)
        if joint:
            tuned, seconds, fields = tune(a) if beside is None else beside.result()
            if beside is not None:  # the other seeds' windows are the level chunk's
                fields.update(zip(("window", "task_window"), select_seeds(
                    self.slots.mask(joint), (fields["window"], fields["task_window"]),
                    (a.window, a.task_window))))
            a = a.replace(**fields)
        self.slots.arrays = a
        if not joint:
            return out, compile_s
        if out is None:
            return tuned, seconds
        # a seed's rows are zero in the program it did not run in
        add = lambda x, y: x + y  # noqa: E731
        return (out._replace(stats=jax.tree.map(add, out.stats, tuned.stats),
                             windows=jax.tree.map(add, out.windows, tuned.windows),
                             joint_metrics=tuned.joint_metrics,
                             joint_learned=tuned.joint_learned),
                compile_s + seconds)

    def level_args(self, controls: list[SeedControls], active: list[bool], a) -> tuple:
        """The level chunk's arguments on the state ``a`` (``TrainArrays``)."""
        slots = self.slots
        column = lambda name, dtype: slots.per_seed(  # noqa: E731
            [getattr(c, name) for c in controls], dtype)
        tick = ChunkControls(column("option", jnp.int32), column("start", jnp.int32),
                             column("teleport", bool), column("keep_episodes", bool),
                             column("side_cost", jnp.float32), column("gamma", jnp.float32))
        return (a.state, slots.per_seed(active, bool), a.bank, a.learned, tick,
                (a.window, a.task_window),
                slots.per_seed([[c.window, c.task_window] for c in controls], jnp.int32))

    def level_ahead(self, ahead: CompileAhead, controls: list[SeedControls], shapes) -> None:
        """Compile the level chunk on ``ahead``'s thread, for the state's ``shapes`` (before
        the state exists)."""
        if self.level_program is None and ahead.on:
            args = self.level_args(controls, [True] * len(controls), shapes)
            self.level_program = ahead.submit("level_chunk", self._compile_level, args)

    def level(self, controls: list[SeedControls], active: list[bool], describe, a):
        """The level chunk for the ``active`` seeds (levels and fine-tuning turns) on the
        state ``a``: its outputs, the seconds spent compiling and the state's new fields."""
        args = self.level_args(controls, active, a)
        # one compile serves every level (ids are traced)
        self.level_program, compile_s = resolve(self.level_program, args, self._compile_level)
        state, stats, metrics, (window, task_window), windows, finite = self.level_program(*args)
        # [S, U, ...], the same on every process
        stats, windows, finite = dist.gather((stats, windows, finite))
        metrics = float64(dist.gather(metrics)) if self.metrics else None
        if not finite.all():
            raise NonFiniteError(f"non-finite learner parameters in {describe()}")
        return (ChunkOut(stats, windows, metrics), compile_s,
                dict(state=state, window=window, task_window=task_window))

    def _compile_level(self, args: tuple):
        return self.engine.compile("chunk", self.engine.chunk, args, donate=(0,),
                                   busy=CHUNK_BUSY)

    def joint_args(self, seeds: list[int], side_cost, gammas, sizes, a=None) -> tuple:
        """Joint fine-tuning's chunk's arguments: these seeds run, the others keep their
        state (``a``: the state, default the slots')."""
        slots = self.slots
        a = slots.arrays if a is None else a
        return (a.joint, slots.per_seed([s in seeds for s in range(len(slots))], bool),
                a.learned, slots.per_seed(side_cost, jnp.float32),
                slots.per_seed(gammas, jnp.float32), (a.window, a.task_window),
                slots.per_seed(sizes, jnp.int32))

    def joint_ahead(self, ahead: CompileAhead, side_cost, gammas, sizes, a) -> None:
        """Compile joint fine-tuning's chunk on ``ahead``'s thread, for the state ``a`` or its
        shapes (known from the start: the joint state is built with the trainer)."""
        if self.joint_program is None and ahead.on:
            make = lambda a: self.joint_args([], side_cost, gammas, sizes, a)  # noqa: E731
            self.joint_program = ahead.submit("joint_chunk", self._compile_joint,
                                              arguments(make, a))

    def _compile_joint(self, args: tuple):
        return self.engine.compile("joint_chunk", self.engine.joint_chunk, args, donate=(0,),
                                   busy=CHUNK_BUSY)

    def joint(self, seeds: list[int], side_cost, gammas, sizes, describe, a):
        """Joint fine-tuning's chunk for these seeds on the state ``a`` (the others keep
        theirs): its outputs, the seconds spent compiling and the state's new fields."""
        args = self.joint_args(seeds, side_cost, gammas, sizes, a)
        self.joint_program, compile_s = resolve(self.joint_program, args, self._compile_joint)
        state, stats, metrics, (window, task_window), windows, finite = self.joint_program(*args)
        stats, windows, finite = dist.gather((stats, windows, finite))
        if not finite.all():
            raise NonFiniteError(f"non-finite learner parameters in {describe()}")
        out = ChunkOut(stats, windows)
        if self.metrics:  # collectives: every process gathers
            out = out._replace(joint_metrics=float64(dist.gather(metrics)),
                               joint_learned=np.asarray(dist.gather(a.learned)))
        return out, compile_s, dict(joint=state, window=window, task_window=task_window)


def float64(metrics: dict) -> dict:
    """Learner metrics as float64 host arrays (the stages average them)."""
    return {name: np.asarray(value, np.float64) for name, value in metrics.items()}
