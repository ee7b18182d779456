"""The trainer's level steps: counting each chunk toward the seeds' levels, a level's
budget, its acceptance gate, and freezing a finished level's learner into the bank.

``LevelPhase`` is mixed into ``HierarchyTrainer`` (``smjax.train.loop``), whose state it
uses: ``state.level`` holds each seed's ``LevelCounters`` (in fine-tuning turns, the
turn's). Fine-tuning's own steps are ``smjax.train.finetune.FinetunePhase``'s.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.train import distributed as dist
from smjax.train.config import TrainConfig
from smjax.train.seed_arrays import fold_in, freeze, local


class LevelPhase:
    """The trainer's level steps (mixed into ``HierarchyTrainer``)."""

    def _account(self, stats, windows) -> tuple[list[int], list[int]]:
        """Count a chunk's episodes, steps and windows (learner's, task's: ``Engine._chunk``);
        record the curves; the seeds whose running success reached the threshold (levels), and
        the fine-tuning seeds whose task success reached theirs."""
        task_candidates = [s for s in self._training() if self._finetuning(s)
                           and self._account_task(stats, windows[1], s)]
        candidates = []
        steps_per_update = self.cfg.num_envs * self.cfg.rollout_ticks
        for s in self._training():
            plan, cfg, seed, c = self._plan(s), self._level_cfg(s), self.seeds[s], self.state.level[s]
            rows = c.count(stats.env_episodes[s], *(x[s] for x in windows[0]), steps_per_update)
            for episodes, env_steps, running in rows:
                if not self._finetuning(s):  # (fine-tuning records the task's curve)
                    self.state.curves.append([seed, plan.level, plan.name, episodes, env_steps,
                                              running, s])
                if self._tb is not None and running is not None:
                    tag = self._tb_level_tag(s)
                    self._tb.add_scalar(f"{tag}/running_success", running, env_steps)
                    self._tb.add_scalar(f"{tag}/episodes", episodes, env_steps)
            if (c.running is not None and c.running >= cfg.threshold
                    and not self._finetuning(s) and self._has_threshold(plan.option)):
                candidates.append(s)
        return candidates, task_candidates

    def _has_threshold(self, option: int) -> bool:
        """A level can end at its threshold: an option's success lies in [0, 1]; the root's
        (option 0) unless it is a return on no known scale (CartPole's, tens, would pass
        0.8 at once): such a root level spends its whole budget instead."""
        return option != 0 or self.engine.root_has_threshold

    def _budget_spent(self, cfg: TrainConfig, s: int) -> bool:
        c = self.state.level[s]
        return c.episodes >= cfg.max_episodes_per_level or bool(
            cfg.max_steps_per_level and c.env_steps >= cfg.max_steps_per_level)

    def _accept(self, candidates: list[int]) -> list[int]:
        """Seeds (of ``candidates``, whose running success reached the threshold) whose
        level ends now: all of them without the gate; with it, those whose frozen policy
        passes a gate attempt (tried every ``gate_interval`` chunks, and once more when
        the budget is spent)."""
        st, a = self.state, self.arrays
        if not self.cfg.gate or not candidates:
            return candidates
        due = [s for s in candidates if st.chunks >= st.level[s].gate_next
               or self._budget_spent(self._level_cfg(s), s)]
        if not due:
            return []
        S = len(self.seeds)
        # the attempt number varies the gate's episodes between attempts, deterministically
        keys = fold_in(a.keys, jnp.asarray(st.chunks, jnp.uint32))
        plans = [self._plan(s) for s in range(S)]
        # one vmapped call for all seeds; those not due are skipped (their results unused)
        result, compile_s = self.engine.gate(
            keys, a.state, a.bank, a.learned, [p.option for p in plans],
            [p.start for p in plans], [s in due for s in range(S)],
            [self._level_cfg(s).threshold for s in range(S)], place=self._place_small)
        st.compile_seconds += compile_s
        result = dist.gather(result)
        passed = []
        for s in due:
            c, cfg = st.level[s], self._level_cfg(s)
            success = c.record_gate(result, s, st.chunks + cfg.gate_interval)
            if self._tb is not None:
                self._tb.add_scalar(f"{self._tb_level_tag(s)}/gate_success", success, c.env_steps)
                self._tb.add_scalar(f"{self._tb_level_tag(s)}/gate_uncalled", c.gate_uncalled,
                                    c.env_steps)
            if success >= cfg.threshold:
                passed.append(s)
        return passed

    def _freeze_learners(self, seeds: list[int]) -> None:
        """Store these seeds' learner params in their banks at the option they train."""
        a = jax.tree.map(local, self.arrays)
        bank, learned = freeze(self._mask(seeds), self._options(), a.state.learner.params,
                               a.bank, a.learned)
        self.arrays = a.replace(bank=bank, learned=learned)
        self._place()

    def _finish_levels(self, seeds: list[int]) -> None:
        """Freeze these seeds' learners into the bank and record their levels."""
        if not seeds:
            return
        self._freeze_learners(seeds)
        for s in seeds:
            self.state.finish_level(s)
        self._evaluate_before([s for s in seeds if self._finetuning(s)])
