"""The training progress bar: levels finished by all seeds, and where each seed stands.

Seeds train their levels at their own pace, so one bar counts (seed, stage) pairs finished
out of seeds x stages (a stage: one level, or fine-tuning); its postfix shows how many
seeds are at each level (``seeds_at=L1:1 L2:1``, ``FT``: fine-tuning), the
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
        stages = trainer.num_stages  # the levels, and fine-tuning where it runs
        done = int(sum(trainer.state.stage))
        what = f"{levels} level{'s' * (levels > 1)}"
        what = f"({what} + fine-tune)" if stages > levels else what
        self.bar = tqdm(total=seeds * stages, initial=done, unit="stage", leave=True,
                        desc=f"{seeds} seed{'s' * (seeds > 1)} x {what}")

    def draw(self, chunk_seconds: float) -> None:
        trainer, st = self.trainer, self.trainer.state
        cfg = trainer.cfg
        training = trainer._training()
        steps = cfg.updates_per_chunk * cfg.num_envs * cfg.rollout_ticks * len(training)
        self.bar.n = int(sum(st.stage))
        at = [f"L{trainer._plan(s).level}" if not trainer._finetuning(s) else "FT"
              for s in training]
        order = sorted(set(at), key=lambda a: (a == "FT", a))  # levels, then fine-tuning
        extra = {"seeds_at": " ".join(f"{a}:{at.count(a)}" for a in order)} if at else {}
        levels = [s for s in training if not trainer._finetuning(s)]
        runs = [st.level[s].running for s in levels if st.level[s].running is not None]
        gates = [st.level[s].gate_success for s in levels if st.level[s].gate_success is not None]
        tasks = [st.finetune[s].task_running for s in training
                 if trainer._finetuning(s) and st.finetune[s].task_running is not None]
        if tasks:  # fine-tuning: the teleport-free task success
            extra["task"] = f"{np.mean(tasks):.2f}"
        if runs:
            extra["success"] = f"{np.mean(runs):.2f}"
        if gates:
            extra["gate"] = f"{np.mean(gates):.2f}"
        by_steps = any(trainer._level_cfg(s).max_steps_per_level for s in training)
        counts = "env_steps" if by_steps else "episodes"
        if training:
            extra[counts] = f"{np.mean([getattr(st.level[s], counts) for s in training]):,.0f}"
            extra["steps_s"] = f"{steps / max(chunk_seconds, 1e-9):,.0f}"
        self.bar.set_postfix(**extra)
        self.bar.refresh()

    def close(self) -> None:
        self.bar.n = int(sum(self.trainer.state.stage))
        self.bar.refresh()
        self.bar.close()
