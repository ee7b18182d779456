"""Side jobs of training as hooks of the driver loop (:mod:`smjax.train.loop`).

After every chunk the loop hands each hook a ``ChunkReport`` (the scalars the stages
logged, where every seed stands, whether a level, turn or phase ended), in the spirit of
Brax's ``progress_fn``: the loop itself writes and prints nothing, its hooks do. Once the
trained hierarchies are evaluated, ``run`` hands each hook a ``ResultsReport`` (a sweep: one
per point). The hooks here: TensorBoard (``TensorBoardHook``) and checkpoints
(``CheckpointHook``, which also restores them); the progress bar is
:class:`smjax.train.progress.ProgressBar`, the run's files
:class:`smjax.train.results.ResultsHook`, its curves.png ``smjax.viz.plots.PlotHook``.
"""
from __future__ import annotations

import importlib
import json
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.timeline import TIMELINE
from smjax.train import checkpoint as ckpt
from smjax.train import distributed as dist
from smjax.train.config import RUN_SETTINGS, TrainConfig
from smjax.train.restorable import check_restorable
from smjax.train.stages import Scalar, SeedStatus
from smjax.train.state import TrainArrays, TrainerState


@dataclass(frozen=True)
class ChunkReport:
    """What a chunk did, for the hooks."""
    chunk: int                  # chunks run so far
    seconds: float              # the chunk's wall time
    steps: int                  # env steps it trained (every training seed's)
    scalars: list[Scalar]       # the stages' numbers, each at its own env step
    seeds: list[SeedStatus]     # where each seed still training stands now
    stages_done: int            # (seed, stage) pairs finished
    stage_ended: bool           # a level, turn or phase ended in this chunk


@dataclass(frozen=True)
class ResultsReport:
    """A run's results, or one sweep point's, for the hooks."""
    out_dir: Path | None        # where its files go (a sweep: OUT/point-<k>); None: nowhere
    results: dict               # results.json's content
    raw: dict                   # the trainer's raw results (a sweep: the point's slots)
    overrides: dict | None = None   # a sweep point's swept values (None: not a sweep)


class Hook:
    """A side job of training; override what it needs. ``modules``: what its later calls
    import, imported on a thread once training starts (``import_ahead``)."""

    modules: tuple[str, ...] = ()

    def prepare(self, trainer) -> None:
        """The trainer is being built: its seeds and stages are known, its programs are
        being compiled (a first run of these settings: tens of seconds on a CPU) or loaded
        from the cache, and nothing has trained."""

    def start(self, trainer) -> None:
        """Training starts (or resumes) with ``trainer``'s state."""

    def chunk(self, trainer, report: ChunkReport) -> None:
        """A chunk ran and the stages decided on it."""

    def end(self, trainer) -> None:
        """Every seed finished training (evaluation follows, then ``trainer.results_due``
        calls of ``results``: one for a run, one per sweep point, none where the trainer is
        run on its own, outside ``smjax.train.run``)."""

    def results(self, trainer, report: ResultsReport) -> None:
        """The evaluated results are ready: once per run, once per point of a sweep (in
        ``sweep.json``'s order). Every process gets them, as it gets the chunks; a hook
        that writes files writes on process 0 (``smjax.train.distributed.is_writer``)."""

    def close(self) -> None:
        """The trainer stops, whether it finished or an error (or Ctrl-C) ended it: finish
        what is under way. Raises nothing."""


def import_ahead(hooks) -> threading.Thread | None:
    """Import the hooks' ``modules`` on a thread: a checkpoint's orbax and a plot's
    matplotlib cost ~0.5 s of imports that would otherwise stop training where first
    used, while the chunks leave the interpreter idle (XLA runs without the GIL). A module
    that fails here is imported again, and fails, where it is used."""
    names = [name for hook in hooks for name in getattr(hook, "modules", ())]
    if not names:
        return None

    def load() -> None:
        for name in names:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - raised again where it is used
                pass

    # not a daemon: a process exiting mid-import would abort
    thread = threading.Thread(target=load, name="smjax-import-ahead")
    thread.start()
    return thread


def snapshot(arrays):
    """The arrays as they are now, for a write that runs while training goes on: the next
    chunk reuses (donates) the state's device buffers. A copy on the device, made without
    compiling anything (on a GPU it takes milliseconds, where reading 100 seeds' 2.6 GB to
    the host takes seconds); where the device has no room for it, a copy on the host."""
    try:
        return jax.device_put(arrays, may_alias=False)
    except jax.errors.JaxRuntimeError as err:
        if "RESOURCE_EXHAUSTED" not in str(err):
            raise
        # a host view of a CPU buffer would change with it: copied
        return jax.tree.map(np.array, dist.gather(arrays))


class TensorBoardHook(Hook):
    """Every scalar of the stages to TensorBoard event files in ``directory``."""

    def __init__(self, directory: str | Path):
        from tensorboardX import SummaryWriter

        self.writer = SummaryWriter(str(directory))

    def chunk(self, trainer, report: ChunkReport) -> None:
        for scalar in report.scalars:
            self.writer.add_scalar(scalar.name, scalar.value, scalar.step)

    def end(self, trainer) -> None:
        self.writer.close()


class CheckpointHook(Hook):
    """Checkpoints in ``out_dir`` every ``cfg.run.checkpoint_every`` seconds and when a stage
    ends; with several processes every process runs it (saving is collective) and process
    0 writes. ``run_meta``: the run's identity (what a resume must match).

    A stage end is written at once unless a checkpoint was written less than
    ``STAGE_GAP_WRITES`` times the last write's duration ago; then it is written at the
    first chunk after that gap. With many seeds, each ending its levels and turns in a
    chunk of its own, one write then covers several ends, and writes stay a small part of
    the wall time, while no stage end waits more than the gap for its checkpoint. The
    last one (every stage done) is always written at once."""

    STAGE_GAP_WRITES = 20
    modules = ("orbax.checkpoint",)

    def __init__(self, out_dir: str | Path, cfg: TrainConfig, run_meta: dict):
        self.out_dir, self.run_meta, self.every = out_dir, run_meta, cfg.run.checkpoint_every
        # the settings a resume starts from unless told otherwise (not the run's identity)
        self.settings = {k: getattr(cfg, k) for k in RUN_SETTINGS}
        self.last_save = time.perf_counter()
        self.last_write_seconds = 0.0
        self.wrote_once = False
        self.stage_pending = False  # a stage ended since the last write
        self.writer: ThreadPoolExecutor | None = None  # the writes' thread, made at the first
        self.pending: Future | None = None  # the write under way (or done, not yet checked)

    def chunk(self, trainer, report: ChunkReport) -> None:
        self.raise_failed_write()
        self.stage_pending |= report.stage_ended
        if self.due() or (self.stage_pending and self.stage_write_due(trainer)):
            with TIMELINE.span("checkpoint writes"):
                self.save(trainer)

    def close(self) -> None:
        """The trainer stops, however it stops: the write under way finishes (the checkpoint
        before it stays in force until it has). The last write (every stage done) runs
        beside the evaluation; its failure is said in one line, the run's results stand."""
        try:
            with TIMELINE.span("checkpoint writes"):
                self.wait()
        except ckpt.CheckpointError as err:
            print(f"smjax: the last checkpoint was not written ({err}); the one before it "
                  f"is in force", file=sys.stderr)
        if self.writer is not None:
            self.writer.shutdown(wait=True)
            self.writer = None

    def write_seconds(self) -> float:
        """How long the last write took; one still under way has taken at least this long."""
        if self.pending is not None and not self.pending.done():
            return max(self.last_write_seconds, time.perf_counter() - self.last_save)
        return self.last_write_seconds

    def wait(self) -> None:
        """Until the write under way is on disk; its failure raised here."""
        pending, self.pending = self.pending, None
        if pending is not None:
            pending.result()

    def raise_failed_write(self) -> None:
        """A write that failed since the last chunk stops the run now, in one line."""
        if self.pending is not None and self.pending.done():
            self.wait()

    def due(self) -> bool:
        due = time.perf_counter() - self.last_save >= self.every
        # clocks differ between processes, and saving is collective: process 0 decides
        return dist.agree(due) if self.every > 0 else due

    def stage_write_due(self, trainer) -> bool:
        """Whether a stage end's checkpoint is written now (process 0 decides)."""
        gap = self.STAGE_GAP_WRITES * self.write_seconds()
        due = (not trainer.training() or not self.wrote_once
               or time.perf_counter() - self.last_save >= gap)
        return dist.agree(due)

    def save(self, trainer) -> None:
        """Checkpoint (collective with several processes: all gather, process 0 writes).

        The arrays are copied here (``snapshot``), and written on a thread while training
        goes on (orbax's writes, their fsyncs and the swap of ``latest.json`` take ~0.25 s
        on a CPU, seconds for many seeds on a GPU); one write at a time, in order. A
        failed write stops the run at the next chunk with its one-line error, the
        checkpoint before it still in force; the run's last write, and one under way when
        the run stops, are waited for (``close``)."""
        self.wait()
        # trained: every stage is done, so a resume only evaluates and writes results
        meta = {"host": trainer.state.to_json(), "run": self.run_meta,
                "settings": self.settings, "format": ckpt.CHECKPOINT_FORMAT,
                "trained": not trainer.training()}
        # a copy as it is now: the host state's lists go on changing while the thread
        # writes the step's manifest and, later, latest.json, which must hold the same
        meta = json.loads(json.dumps(meta))
        arrays = (dist.gather(trainer.arrays) if dist.is_multiprocess()
                  else snapshot(trainer.arrays))
        if dist.is_writer():
            if self.writer is None:
                self.writer = ThreadPoolExecutor(1, thread_name_prefix="smjax-checkpoint")
            self.pending = self.writer.submit(self._write, trainer.state.chunks, arrays, meta)
        self.last_save = time.perf_counter()
        self.wrote_once, self.stage_pending = True, False

    def _write(self, step: int, arrays, meta: dict) -> None:
        began = time.perf_counter()
        try:
            ckpt.save_checkpoint(self.out_dir, step, arrays, meta)
        finally:
            self.last_write_seconds = time.perf_counter() - began
            TIMELINE.inside("checkpoint writes (a thread)", self.last_write_seconds)

    def load(self, like: TrainArrays, num_stages: int, step: str | None = None,
             checked: dict | None = None) -> tuple[TrainArrays, TrainerState] | None:
        """Process 0's checkpoint (its latest, or ``step``), verified against its format,
        its manifest and the plan, the same on every process; ``like``: the run's fresh
        arrays, which a checkpoint of this format holds leaf for leaf; ``checked``:
        ``check_restorable``'s answer where the caller has it. None: no checkpoint."""
        out_dir = self.out_dir
        if checked is None:
            checked = check_restorable(out_dir, step, like.keys.shape[0], num_stages)
        if checked is None:
            return None
        if dist.is_multiprocess():
            stored = jax.tree.map(lambda x: np.zeros(x.shape, x.dtype), like)
            loaded = (ckpt.load_arrays(out_dir, stored, step, verified=True)
                      if dist.is_writer() else stored)
            arrays = jax.tree.map(jnp.asarray, dist.broadcast(loaded))
        else:
            arrays = ckpt.load_arrays(out_dir, like, step, verified=True)
        return arrays, TrainerState.from_json(checked["meta"]["host"])
