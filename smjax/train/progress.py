"""The training progress bar: levels finished by all seeds, and where each seed stands.

Seeds train their levels at their own pace, so one bar counts (seed, level) pairs
finished out of seeds x levels; its postfix shows how many seeds are at each level, the
mean running success of the levels in progress, the mean episodes (or env steps, where a
level has a step budget) spent in them, the last gate success, and env steps per second.
"""
from __future__ import annotations

import numpy as np


class Progress:
    def __init__(self, trainer):
        from tqdm.auto import tqdm

        self.trainer = trainer
        seeds, levels = len(trainer.seeds), len(trainer.plans)
        done = int(sum(trainer.host["stage"]))
        self.bar = tqdm(total=seeds * levels, initial=done, unit="level", leave=True,
                        desc=f"{seeds} seed{'s' * (seeds > 1)} x {levels} level{'s' * (levels > 1)}")

    def draw(self, chunk_seconds: float) -> None:
        trainer, host = self.trainer, self.trainer.host
        cfg = trainer.cfg
        training = trainer._training()
        steps = cfg.updates_per_chunk * cfg.num_envs * cfg.rollout_ticks * len(training)
        self.bar.n = int(sum(host["stage"]))
        at = [trainer._plan(s).level for s in training]
        extra = {"at": " ".join(f"L{lvl}x{at.count(lvl)}" for lvl in sorted(set(at)))} if at else {}
        runs = [host["running"][s] for s in training if host["running"][s] is not None]
        gates = [host["gate_success"][s] for s in training if host["gate_success"][s] is not None]
        if runs:
            extra["success"] = f"{np.mean(runs):.2f}"
        if gates:
            extra["gate"] = f"{np.mean(gates):.2f}"
        by_steps = any(trainer._level_cfg(s).max_steps_per_level for s in training)
        counts = "env_steps" if by_steps else "episodes"
        if training:
            extra[counts] = f"{np.mean([host[counts][s] for s in training]):,.0f}"
            extra["steps_s"] = f"{steps / max(chunk_seconds, 1e-9):,.0f}"
        self.bar.set_postfix(**extra)
        self.bar.refresh()

    def close(self) -> None:
        self.bar.n = int(sum(self.trainer.host["stage"]))
        self.bar.refresh()
        self.bar.close()
