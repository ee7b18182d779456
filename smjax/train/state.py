"""The trainer's state as typed structs: exactly what a checkpoint holds.

``TrainArrays`` is the device state (per seed: keys, learner and environments, the policy
bank and which options are learned). ``TrainerState`` is the host state the loop decides
with: per seed its stage, the counters of the level (or fine-tuning turn) it trains
(``LevelCounters``) and of fine-tuning (``FinetuneCounters``), and the run's records
(results.json's levels, the curves). Both are stored in the layout of
``checkpoint.CHECKPOINT_FORMAT``, the only one a resume reads: the host state as JSON with
one list over seeds per counter (``TrainerState.to_json``, read back whole by
``from_json``), the arrays by leaf position.

The running-success windows are ring buffers on the device, updated inside the compiled
chunk after every update; the chunk returns, per update, which batches form the window
(their float32 totals, newest first) and its episodes; the host keeps no window and only
reduces those in float64 (``_Counters._count``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


@struct.dataclass
class SuccessWindow:
    """A running-success window: the last K updates' batches (per update, the summed
    success of the episodes it counted and their number), newest at ``next - 1`` (mod K).
    Every stored batch holds at least one episode, so K batches always cover a window of
    K episodes: K is the largest window the run uses, each call says its own ``size``.
    Leading axes (seeds) are the caller's; ``push`` works on one window (vmap it)."""
    total: jax.Array  # [..., K] float32 (0 in an empty slot)
    count: jax.Array  # [..., K] int32 (0: an empty slot)
    next: jax.Array   # [...] int32: the slot the next batch goes to

    @classmethod
    def empty(cls, num_seeds: int, slots: int, xp=jnp) -> "SuccessWindow":
        """No batches yet (``xp``: ``numpy`` for host arrays that a program takes in)."""
        return cls(total=xp.zeros((num_seeds, slots), xp.float32),
                   count=xp.zeros((num_seeds, slots), xp.int32),
                   next=xp.zeros((num_seeds,), xp.int32))

    @classmethod
    def pair(cls, num_seeds: int, slots: int, xp=jnp) -> dict:
        """``TrainArrays``' two windows, empty."""
        return {"window": cls.empty(num_seeds, slots, xp),
                "task_window": cls.empty(num_seeds, slots, xp)}

    def push(self, total: jax.Array, count: jax.Array, size: jax.Array):
        """Add a batch of ``count`` episodes (none: nothing added) whose successes sum to
        ``total``; returns the window and, over the most recent whole batches that hold at
        least ``size`` episodes, their totals newest first ([K], 0 past the window) and
        their episodes (0: fewer than ``size`` so far, no running success yet).

        The sum is left to the host (``_Counters._count``): it adds these float32 totals
        in float64, newest first, and divides, so the running success, and every decision
        on it, is the same to the last bit as the mean of a host list of the batches. A
        float32 sum on the device is exact only for integer batch totals, and successes are
        not always 0/1 (e.g. craft's make_stick F_o): it would move the curves' last digits."""
        K = self.count.shape[-1]
        add = count > 0
        at = self.next
        win = SuccessWindow(
            total=jnp.where(add, self.total.at[at].set(total), self.total),
            count=jnp.where(add, self.count.at[at].set(count), self.count),
            next=jnp.where(add, (at + 1) % K, at))
        # newest first; a batch belongs to the window while the newer ones hold < size
        order = (win.next - 1 - jnp.arange(K)) % K
        counts, totals = win.count[order], win.total[order]
        newer = jnp.cumsum(counts) - counts
        inside = newer < size
        seen = jnp.where(inside, counts, 0).sum()
        return win, (jnp.where(inside, totals, 0.0), jnp.where(seen >= size, seen, 0))


@struct.dataclass
class TrainArrays:
    """The device state, per seed (leading axis). A checkpoint stores the leaves by
    position: the fields' order is the checkpoint's layout (``CHECKPOINT_FORMAT``), and a
    field of None (no fine-tuning, no joint fine-tuning) stores no leaves."""
    bank: Any      # the policy bank: params [S, num_options, ...]
    keys: jax.Array
    learned: jax.Array  # [S, num_options] bool
    state: Any     # engine.SeedState: environments, learner, rollout key
    window: Any = None       # SuccessWindow: the learner's, emptied when a level/turn starts
    task_window: Any = None  # SuccessWindow: fine-tuning's whole-task episodes, all turns
    levels_bank: Any = None  # the bank as the levels left it (fine-tuning may hand it back)
    # joint fine-tuning's engine.SeedState (a learner per option: [S, O, ...]; None unless
    # TrainConfig.finetune_mode is "joint")
    joint: Any = None


class _Counters:
    """Counters of gate attempts (``gate_success``, ``gate_attempts``, ``gate_env_steps``,
    ``gate_next``: the first chunk at which the next attempt may run), and of a chunk's
    updates (``episodes``, ``env_steps``; the running success, read from the device's
    window, ``SuccessWindow``)."""

    def _count(self, episodes, totals, seen, steps_per_update: int
               ) -> list[tuple[int, int, float | None]]:
        """Per update (environment episodes; the window's batch totals, newest first, and
        its episodes, 0 while not full: ``SuccessWindow.push``): count it; (episodes,
        env_steps, running success) after it."""
        rows = []
        for e, batches, n in zip(episodes, totals, seen):
            self.episodes += int(e)
            self.env_steps += steps_per_update
            # a sequential float64 sum, newest first (cumsum does not pair up terms as
            # np.sum does): a host list's arithmetic on these float32 totals (zeros past
            # the window add 0)
            total = float(np.cumsum(np.asarray(batches, np.float64))[-1])
            rows.append((self.episodes, self.env_steps, total / int(n) if n else None))
        return rows

    def record_gate(self, result: dict, s: int, next_chunk: int) -> float:
        """Count seed ``s``'s attempt (``result``: the episodes program's, gathered); its
        success."""
        self.gate_success = float(result["success"][s])
        self.gate_uncalled = float(result["uncalled"][s])
        self.gate_attempts += 1
        self.gate_env_steps += int(result["env_steps"][s])
        self.gate_next = next_chunk
        return self.gate_success


@dataclass
class LevelCounters(_Counters):
    """One seed's counters in the level (or fine-tuning turn) it trains."""
    episodes: int = 0
    env_steps: int = 0
    running: float | None = None  # the learner's running success (None: window not full yet)
    reached: bool = False
    gate_success: float | None = None
    # the last attempt's share of environments whose levels above never called the
    # option (left out of gate_success: smjax.options.episodes.first_episodes)
    gate_uncalled: float | None = None
    gate_attempts: int = 0
    gate_env_steps: int = 0
    gate_next: int = 0

    def count(self, episodes, totals, seen, steps_per_update: int
              ) -> list[tuple[int, int, float | None]]:
        """Count a chunk's updates (per update: environment episodes, the learner window's
        batch totals and episodes); per update, (episodes, env_steps, running) after it."""
        rows = self._count(episodes, totals, seen, steps_per_update)
        self.running = rows[-1][2] if rows else self.running
        return rows


@dataclass
class FinetuneCounters(_Counters):
    """One seed's fine-tuning counters (its phase, over all its turns)."""
    turn: int = 0               # turn index: the option is ``order[turn % len(order)]``
    rested: dict = field(default_factory=dict)  # template -> turns sat out in a row
    episodes: int = 0           # environment episodes of the phase's training chunks
    env_steps: int = 0
    task_running: float | None = None  # teleport-free task success over the window
    gate_success: float | None = None
    gate_uncalled: float | None = None  # the root is always called: 0 once a gate ran
    gate_attempts: int = 0
    gate_env_steps: int = 0
    gate_next: int = 0
    reached: bool = False       # a gate passed
    success_before: float | None = None  # final_success as the levels left the hierarchy
    turns: list = field(default_factory=list)  # [{"template", "episodes", "running_success"}]
    # where the gate never passed: the fine-tuned hierarchy's success on fresh episodes at
    # the phase's end, and which bank the phase handed back ("fine-tuned" or "levels": the
    # better of the two); baseline: the levels' bank was kept when the phase started (what
    # keep_better compares the fine-tuned hierarchy with)
    check_success: float | None = None
    kept: str | None = None
    baseline: bool = False
    # the plateau stop (TrainConfig.finetune_plateau_episodes): the task success of
    # whole-task episodes summed over the block in progress, its episodes, and the mean of
    # every finished block; why the phase ended ("gate", "plateau" or "budget")
    block_success: float = 0.0
    block_episodes: int = 0
    block_means: list = field(default_factory=list)
    stop: str | None = None

    def count(self, episodes, totals, seen, steps_per_update: int
              ) -> list[tuple[int, int, float | None]]:
        """Count a fine-tuning chunk's updates (the task window's batches); per update,
        (episodes, env_steps, task_running) after it."""
        rows = self._count(episodes, totals, seen, steps_per_update)
        self.task_running = rows[-1][2] if rows else self.task_running
        return rows

    def add_to_block(self, success: float, episodes: int, size: int) -> None:
        """Add an update's whole-task episodes (``success``: their summed task success) to
        the block in progress; a block of at least ``size`` episodes is closed (its mean
        appended to ``block_means``) and the next one starts."""
        self.block_success += float(success)
        self.block_episodes += int(episodes)
        if size and self.block_episodes >= size:
            self.block_means.append(self.block_success / self.block_episodes)
            self.block_success, self.block_episodes = 0.0, 0

    def plateaued(self, gain: float) -> bool:
        """The last finished block's mean task success is less than ``gain`` above the one
        before it."""
        means = self.block_means
        return len(means) >= 2 and means[-1] - means[-2] < gain


LEVEL_KEYS = tuple(f.name for f in dataclasses.fields(LevelCounters))
FINETUNE_KEYS = tuple(f.name for f in dataclasses.fields(FinetuneCounters))
# a level's results.json entry: per seed, filled when the seed finishes the level
# (gate_success, gate_uncalled: the last attempt's, None: never tried)
RECORD_KEYS = {"episodes": "episodes", "env_steps": "env_steps", "reached": "reached",
               "final_running_success": "running", "gate_success": "gate_success",
               "gate_uncalled": "gate_uncalled", "gate_attempts": "gate_attempts",
               "gate_env_steps": "gate_env_steps"}


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
        """The checkpoint's host state: per counter a list over seeds (fine-tuning's under
        ``finetune``), the records and the totals."""
        return {"stage": self.stage, "started": self.started, "levels": self.levels,
                "curves": self.curves, "finetune": self.finetune_record(),
                "compile_seconds": self.compile_seconds, "wall_seconds": self.wall_seconds,
                "chunks": self.chunks,
                **{k: [getattr(c, k) for c in self.level] for k in LEVEL_KEYS}}

    @classmethod
    def from_json(cls, host: dict) -> "TrainerState":
        """From ``to_json``'s host state, which holds every counter (a resume checks it
        first: ``missing_counter``)."""
        seeds = range(len(host["stage"]))
        ft = host["finetune"]
        return cls(stage=list(host["stage"]), started=list(host["started"]),
                   level=[LevelCounters(**{k: host[k][s] for k in LEVEL_KEYS}) for s in seeds],
                   finetune=[FinetuneCounters(**{k: ft[k][s] for k in FINETUNE_KEYS})
                             for s in seeds],
                   levels=host["levels"], curves=host["curves"],
                   compile_seconds=host["compile_seconds"], wall_seconds=host["wall_seconds"],
                   chunks=host["chunks"])


def missing_counter(host: dict, num_seeds: int) -> str | None:
    """Which counter or level record of a checkpoint's host state ``TrainerState.from_json``
    would miss (every one ``to_json`` writes, over ``num_seeds`` seeds); None: none."""
    ft = host.get("finetune") or {}
    lists = ([(k, host.get(k)) for k in ("started",) + LEVEL_KEYS]
             + [(f"finetune {k}", ft.get(k)) for k in FINETUNE_KEYS]
             + [(f"levels[{i}] {k}", rec.get(k)) for i, rec in enumerate(host.get("levels", []))
                for k in RECORD_KEYS])
    for name, value in lists:
        if not isinstance(value, list) or len(value) != num_seeds:
            return f"its host state lacks the counter {name} (a list over its {num_seeds} seeds)"
    return None
