"""The trainer's state as typed structs: exactly what a checkpoint holds.

``TrainArrays`` is the device state (per seed: keys, learner and environments, the policy
bank and which options are learned). ``TrainerState`` is the host state the loop decides
with: per seed its stage, the counters of the level (or fine-tuning turn) it trains
(``LevelCounters``) and of fine-tuning (``FinetuneCounters``), and the run's records
(results.json's levels, the curves). Both are stored in the layout of checkpoint format 2
(the host state as JSON with one list over seeds per counter; the arrays by leaf
position), so checkpoints of earlier versions resume.

The running-success windows (``append_window``) are host lists of per-update
[summed success, episodes] batches. They stay on the host: the success is averaged in
float64 over whole updates, and a device window (float32 without ``jax_enable_x64``)
would round differently and could move a threshold crossing.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import jax
from flax import struct


@struct.dataclass
class TrainArrays:
    """The device state, per seed (leading axis). The fields are in the order of the dict
    that checkpoints of earlier versions were written from (leaves are stored by position)."""
    bank: Any      # the policy bank: params [S, num_options, ...]
    keys: jax.Array
    learned: jax.Array  # [S, num_options] bool
    state: Any     # engine.SeedState: environments, learner, rollout key


def append_window(history: list, total: float, count: int, window: int) -> float | None:
    """Add a batch of ``count`` episodes whose successes sum to ``total`` to ``history``
    (trimmed in place to what the window needs); the mean success over the last
    ``window`` episodes, whole batches (None: fewer so far)."""
    if count:
        history.append([total, count])
    total, seen, keep = 0.0, 0, 0
    for s, c in reversed(history):
        total, seen, keep = total + s, seen + c, keep + 1
        if seen >= window:
            break
    del history[:len(history) - keep]
    return total / seen if seen >= window else None


class _Counters:
    """Counters of gate attempts (``gate_success``, ``gate_attempts``, ``gate_env_steps``,
    ``gate_next``: the first chunk at which the next attempt may run), and of a chunk's
    updates (``episodes``, ``env_steps``, a running-success window)."""

    def _count(self, history: list, episodes, success, counted, steps_per_update: int,
               window: int) -> list[tuple[int, int, float | None]]:
        """Per update (environment episodes, summed success, the episodes it counts):
        count it, add it to ``history``; (episodes, env_steps, running success) after it."""
        rows = []
        for e, total, n in zip(episodes, success, counted):
            self.episodes += int(e)
            self.env_steps += steps_per_update
            rows.append((self.episodes, self.env_steps,
                         append_window(history, float(total), int(n), window)))
        return rows

    def record_gate(self, result: dict, s: int, next_chunk: int) -> float:
        """Count seed ``s``'s attempt (``result``: the episodes program's, gathered); its
        success."""
        self.gate_success = float(result["success"][s])
        self.gate_attempts += 1
        self.gate_env_steps += int(result["env_steps"][s])
        self.gate_next = next_chunk
        return self.gate_success


@dataclass
class LevelCounters(_Counters):
    """One seed's counters in the level (or fine-tuning turn) it trains."""
    episodes: int = 0
    env_steps: int = 0
    history: list = field(default_factory=list)  # the learner's success window
    running: float | None = None  # its running success (None: window not full yet)
    reached: bool = False
    gate_success: float | None = None
    gate_attempts: int = 0
    gate_env_steps: int = 0
    gate_next: int = 0

    def count(self, episodes, success, learner_episodes, steps_per_update: int,
              window: int) -> list[tuple[int, int, float | None]]:
        """Count a chunk's updates (per update: environment episodes, the learner's summed
        success and its episodes); per update, (episodes, env_steps, running) after it."""
        rows = self._count(self.history, episodes, success, learner_episodes, steps_per_update,
                           window)
        self.running = rows[-1][2] if rows else self.running
        return rows


@dataclass
class FinetuneCounters(_Counters):
    """One seed's fine-tuning counters (its phase, over all its turns)."""
    turn: int = 0               # turns started (the option is the turn's, round robin)
    episodes: int = 0           # environment episodes of the phase's training chunks
    env_steps: int = 0
    task_history: list = field(default_factory=list)  # whole-task episodes' window
    task_running: float | None = None  # teleport-free task success over the window
    gate_success: float | None = None
    gate_attempts: int = 0
    gate_env_steps: int = 0
    gate_next: int = 0
    reached: bool = False       # a gate passed
    success_before: float | None = None  # final_success as the levels left the hierarchy
    turns: list = field(default_factory=list)  # [{"template", "episodes", "running_success"}]

    def count(self, episodes, success, task_episodes, steps_per_update: int,
              window: int) -> list[tuple[int, int, float | None]]:
        """Count a fine-tuning chunk's updates; per update, (episodes, env_steps,
        task_running) after it."""
        rows = self._count(self.task_history, episodes, success, task_episodes,
                           steps_per_update, window)
        self.task_running = rows[-1][2] if rows else self.task_running
        return rows


LEVEL_KEYS = tuple(f.name for f in dataclasses.fields(LevelCounters))
FINETUNE_KEYS = tuple(f.name for f in dataclasses.fields(FinetuneCounters))
# a level's results.json entry: per seed, filled when the seed finishes the level
# (gate_success: the last attempt's, None: never tried)
RECORD_KEYS = {"episodes": "episodes", "env_steps": "env_steps", "reached": "reached",
               "final_running_success": "running", "gate_success": "gate_success",
               "gate_attempts": "gate_attempts", "gate_env_steps": "gate_env_steps"}


@dataclass
class TrainerState:
    """The host state: per seed its stage (the plan it trains; ``len(plans)``:
    fine-tuning; ``num_stages``: done) and counters; the run's records and totals."""
    stage: list[int]
    started: list[bool]  # the seed's current level (or turn) has been set up
    level: list[LevelCounters]
    finetune: list[FinetuneCounters]
    levels: list[dict]   # results.json's per-level records
    curves: list[list]   # [seed, level, template, episodes, env_steps, running, slot]
    compile_seconds: float = 0.0
    wall_seconds: float = 0.0
    chunks: int = 0

    @classmethod
    def new(cls, plans, num_seeds: int) -> "TrainerState":
        S = num_seeds
        levels = [{"template": p.name, "level": p.level,
                   **{k: [None] * S for k in RECORD_KEYS}} for p in plans]
        return cls(stage=[0] * S, started=[False] * S,
                   level=[LevelCounters() for _ in range(S)],
                   finetune=[FinetuneCounters() for _ in range(S)], levels=levels, curves=[])

    def start(self, s: int) -> None:
        """Seed ``s`` starts a level or turn: fresh level counters."""
        self.level[s] = LevelCounters()
        self.started[s] = True

    def finish_level(self, s: int) -> None:
        """Record seed ``s``'s level in its results entry; on to its next stage."""
        record, counters = self.levels[self.stage[s]], self.level[s]
        for name, key in RECORD_KEYS.items():
            record[name][s] = getattr(counters, key)
        self.stage[s] += 1
        self.started[s] = False

    def finetune_record(self) -> dict:
        """Fine-tuning's counters, per counter a list over seeds."""
        return {k: [getattr(c, k) for c in self.finetune] for k in FINETUNE_KEYS}

    def to_json(self) -> dict:
        """The checkpoint's host state (the layout of format 2)."""
        return {"stage": self.stage, "started": self.started, "levels": self.levels,
                "curves": self.curves, "finetune": self.finetune_record(),
                "compile_seconds": self.compile_seconds, "wall_seconds": self.wall_seconds,
                "chunks": self.chunks,
                **{k: [getattr(c, k) for c in self.level] for k in LEVEL_KEYS}}

    @classmethod
    def from_json(cls, host: dict) -> "TrainerState":
        seeds = range(len(host["stage"]))
        ft = host["finetune"]
        return cls(stage=list(host["stage"]), started=list(host["started"]),
                   level=[LevelCounters(**{k: host[k][s] for k in LEVEL_KEYS}) for s in seeds],
                   finetune=[FinetuneCounters(**{k: ft[k][s] for k in FINETUNE_KEYS})
                             for s in seeds],
                   levels=host["levels"], curves=host["curves"],
                   compile_seconds=host["compile_seconds"], wall_seconds=host["wall_seconds"],
                   chunks=host["chunks"])
