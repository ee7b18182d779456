"""What a stage of training is, and the values it exchanges with the driver loop.

Every seed is in one stage at a time: one of its levels (``LevelStage``,
:mod:`smjax.train.levels`), fine-tuning (``FinetuneStage``, :mod:`smjax.train.finetune`),
or done. All seeds still run in one compiled chunk, so a stage answers per seed: what the
seed's next chunk does (``SeedControls``), what a chunk's statistics count toward
(``account``), which of its seeds end now (``decide``) and what ending does (``finish``).
The counters a stage decides with live in ``TrainerState`` (``state.level``,
``state.finetune``), which every call receives: that state is what a checkpoint holds, so
a stage keeps nothing a resume would lose.

The driver loop (:mod:`smjax.train.loop`) calls, per chunk: ``controls`` for every seed,
the compiled chunk, ``account`` (later stages first), ``decide`` and, where something
ended, ``finish`` (stages in order), then starts what comes next for the ended seeds.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import numpy as np

from smjax.train.plans import LevelPlan
from smjax.train.state import TrainerState


@dataclass(frozen=True)
class SeedControls:
    """What one seed's next chunk does (the level chunk's per-seed inputs)."""
    option: int            # the option its learner trains
    start: int             # the option its episodes start from
    teleport: bool         # options not learned yet are teleported (levels) or not (fine-tuning)
    keep_episodes: bool    # episodes in flight go on when the learner's option ends
    side_cost: float       # weight of the templates' side cost in the learner's reward
    gamma: float           # the learner's discount
    window: int            # episodes in the learner's running-success window
    task_window: int       # episodes in the whole-task window (0: no whole-task episodes)
    threshold: float       # the running success at which the option's level may end
    joint: bool = False    # trains in joint fine-tuning's program instead of the level chunk


@dataclass(frozen=True)
class Scalar:
    """A number for the logging hooks (TensorBoard): its name, value and env step."""
    name: str
    value: float
    step: int


class ChunkOut(NamedTuple):
    """A chunk's statistics for the stages: ``stats`` (``TickStats`` totals, [S, U]),
    ``windows`` (the learner's and the task's window batches, [S, U, ...]), the learner
    metrics of the level chunk ({name: float64 [S, U]}) and of joint fine-tuning ({name:
    float64 [S, U, O]}, with the learned options [S, O]); metrics are None unless they were
    gathered."""
    stats: Any
    windows: Any
    metrics: dict | None = None
    joint_metrics: dict | None = None
    joint_learned: np.ndarray | None = None


@dataclass(frozen=True)
class SeedStatus:
    """Where one training seed stands, for the progress hook."""
    where: str                  # "L2": at level 2; "FT": fine-tuning
    running: float | None       # the learner's running success at its level
    gate: float | None          # its level's last gate success
    task: float | None          # fine-tuning's whole-task running success
    episodes: int               # in its level or turn
    env_steps: int
    by_steps: bool              # its level's budget counts env steps, not episodes


@dataclass
class Ends:
    """The seeds whose level, fine-tuning turn or fine-tuning phase ends after a chunk."""
    levels: list[int] = field(default_factory=list)
    turns: list[int] = field(default_factory=list)
    phases: list[int] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.levels or self.turns or self.phases)


class Stage(Protocol):
    """A stage of training, for the seeds it holds (``holds``)."""

    def holds(self, st: TrainerState, s: int) -> bool:
        """Seed ``s`` is in this stage."""

    def plan(self, st: TrainerState, s: int) -> LevelPlan:
        """The level seed ``s`` trains (in fine-tuning: the option whose turn it is)."""

    def controls(self, st: TrainerState, s: int) -> SeedControls:
        """What seed ``s``'s next chunk does."""

    def account(self, st: TrainerState, seeds: list[int], out: ChunkOut) -> list[Scalar]:
        """Count the chunk toward these seeds' counters and record their curves."""

    def decide(self, st: TrainerState, seeds: list[int], controls: list[SeedControls],
               ends: Ends) -> list[Scalar]:
        """Run the gates due for these seeds; add those whose level, turn or phase ends
        to ``ends`` (``controls``: every seed's in the chunk)."""

    def finish(self, st: TrainerState, ends: Ends, options: list[int]) -> None:
        """What ending does for the seeds in ``ends`` it concerns (``options``: per seed,
        the option it trained in the chunk)."""

    def status(self, st: TrainerState, s: int) -> SeedStatus:
        """Where seed ``s`` stands."""


def learner_scalars(means: dict, s: int, tag: str, step: int) -> list[Scalar]:
    """Seed ``s``'s learner metrics of a chunk ({name: [S, U]}: the mean over its updates)."""
    return [Scalar(f"{tag}/learner/{name}", float(np.mean(value[s])), step)
            for name, value in means.items() if value.ndim == 2]
