"""The training progress bar: levels finished by all seeds, and where each seed stands.

Seeds train their levels at their own pace, so one bar counts (seed, stage) pairs finished
out of seeds x stages (a stage: one level, or fine-tuning); its postfix shows how many
seeds are at each level (``seeds_at=L1:1 L2:1``, ``FT``: fine-tuning), the
mean running success of the levels in progress, the mean episodes (or env steps, where a
level has a step budget) spent in them, the last gate success, and env steps per second.
It is the only hook that prints (to stderr, through tqdm).
"""
from __future__ import annotations

import numpy as np

from smjax.train.hooks import ChunkReport, Hook


# the bar's postfix until the first chunk
PREPARING = "compiling or loading the programs"


class ProgressBar(Hook):
    """The progress bar as a hook of the driver loop."""

    def __init__(self):
        self.bar = None

    def prepare(self, trainer) -> None:
        """The bar from the moment the run's shape is known, saying what the seconds before
        the first chunk are spent on (a first run compiles for tens of seconds)."""
        from tqdm.auto import tqdm

        seeds, levels = len(trainer.seeds), len(trainer.plans)
        stages = trainer.num_stages  # the levels, and fine-tuning where it runs
        what = f"{levels} level{'s' * (levels > 1)}"
        what = f"({what} + fine-tune)" if stages > levels else what
        self.bar = tqdm(total=seeds * stages, initial=int(sum(trainer.state.stage)),
                        unit="stage", leave=True,
                        desc=f"{seeds} seed{'s' * (seeds > 1)} x {what}")
        self.bar.set_postfix_str(PREPARING)

    def start(self, trainer) -> None:
        if self.bar is None:  # a trainer that did not prepare its hooks
            self.prepare(trainer)
        self.bar.n = int(sum(trainer.state.stage))  # a resumed run's stages done
        self.bar.refresh()

    def chunk(self, trainer, report: ChunkReport) -> None:
        self.bar.n = report.stages_done
        self.bar.set_postfix(**postfix(report))
        self.bar.refresh()

    def end(self, trainer) -> None:
        self.bar.n = int(sum(trainer.state.stage))
        self.bar.refresh()
        self.bar.close()

    def close(self) -> None:
        """A run that stopped before its first chunk (a refused setting, Ctrl-C) leaves no
        bar behind its message; one that trained keeps the bar where it stopped."""
        if self.bar is not None and not self.bar.disable:
            if self.bar.postfix == PREPARING:
                self.bar.leave = False
            self.bar.close()


def postfix(report: ChunkReport) -> dict:
    """The bar's postfix: where the seeds are and how they do."""
    seeds = report.seeds
    at = [s.where for s in seeds]
    order = sorted(set(at), key=lambda a: (a == "FT", a))  # levels, then fine-tuning
    extra = {"seeds_at": " ".join(f"{a}:{at.count(a)}" for a in order)} if at else {}
    runs = [s.running for s in seeds if s.running is not None]
    gates = [s.gate for s in seeds if s.gate is not None]
    tasks = [s.task for s in seeds if s.task is not None]
    if tasks:  # fine-tuning: the teleport-free task success
        extra["task"] = f"{np.mean(tasks):.2f}"
    if runs:
        extra["success"] = f"{np.mean(runs):.2f}"
    if gates:
        extra["gate"] = f"{np.mean(gates):.2f}"
    counts = "env_steps" if any(s.by_steps for s in seeds) else "episodes"
    if seeds:
        extra[counts] = f"{np.mean([getattr(s, counts) for s in seeds]):,.0f}"
        extra["steps_s"] = f"{report.steps / max(report.seconds, 1e-9):,.0f}"
    return extra
