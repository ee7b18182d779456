"""The level stage: a seed trains one option at a time, top-down (or as its method plans).

A chunk counts toward each seed's level (``LevelCounters`` in ``state.level``); a level
ends when the learner's running success reaches its threshold and, with the gate on, the
learner as it will be frozen passes that threshold on fresh episodes; or when its budget
(episodes, env steps) is spent. Its learner is then frozen into the seed's policy bank and
the seed moves on to its next level (or to fine-tuning, ``smjax.train.finetune``).
"""
from __future__ import annotations

import jax.numpy as jnp

from smjax.train import distributed as dist
from smjax.train.ahead import arguments
from smjax.train.config import LevelSettings, TrainConfig
from smjax.train.plans import LevelPlan
from smjax.train.seed_arrays import fold_in, freeze
from smjax.train.slots import Slots
from smjax.train.stages import (
    ChunkOut, Ends, Scalar, SeedControls, SeedStatus, learner_scalars,
)
from smjax.train.state import TrainerState


def level_tag(seed: int, plan: LevelPlan) -> str:
    """A seed's logging prefix at a level."""
    return f"seed_{seed}/level_{plan.level}_{plan.name}"


def count_level(st: TrainerState, s: int, out: ChunkOut, steps_per_update: int, tag: str
                ) -> tuple[list, list[Scalar]]:
    """Count a chunk's updates toward seed ``s``'s level counters (in fine-tuning turns,
    the turn's): per update (episodes, env_steps, running success) after it, and their
    scalars under ``tag``."""
    rows = st.level[s].count(out.stats.env_episodes[s], *(x[s] for x in out.windows[0]),
                             steps_per_update)
    scalars = []
    for episodes, env_steps, running in rows:
        if running is not None:
            scalars += [Scalar(f"{tag}/running_success", running, env_steps),
                        Scalar(f"{tag}/episodes", episodes, env_steps)]
    return rows, scalars


class LevelStage:
    """Seeds at one of the planned levels (``st.stage[s] < len(plans)``)."""

    def __init__(self, engine, cfg: TrainConfig, plans: list[LevelPlan], slots: Slots):
        self.engine, self.cfg, self.plans, self.slots = engine, cfg, plans, slots
        self.candidates: list[int] = []  # seeds whose running success reached the threshold

    def holds(self, st: TrainerState, s: int) -> bool:
        return st.stage[s] < len(self.plans)

    def plan(self, st: TrainerState, s: int) -> LevelPlan:
        """Seed ``s``'s level (a seed past every level: the last one)."""
        return self.plans[min(st.stage[s], len(self.plans) - 1)]

    def level_cfg(self, st: TrainerState, s: int) -> LevelSettings:
        return self.cfg.for_level(self.plan(st, s).name)

    def controls(self, st: TrainerState, s: int) -> SeedControls:
        """A level's chunk: teleports on, the level's discount, window and threshold."""
        plan, level = self.plan(st, s), self.level_cfg(st, s)
        return SeedControls(
            option=plan.option, start=plan.start, teleport=True,
            keep_episodes=self.cfg.continue_episodes, side_cost=self.cfg.level_side_cost_weight,
            gamma=self.slots.level_gamma(plan.name, s), window=level.success_window,
            task_window=0, threshold=level.threshold)

    def status(self, st: TrainerState, s: int) -> SeedStatus:
        c = st.level[s]
        return SeedStatus(where=f"L{self.plan(st, s).level}", running=c.running,
                          gate=c.gate_success, task=None, episodes=c.episodes,
                          env_steps=c.env_steps,
                          by_steps=bool(self.level_cfg(st, s).max_steps_per_level))

    def account(self, st: TrainerState, seeds: list[int], out: ChunkOut) -> list[Scalar]:
        """Count the chunk toward these seeds' levels and record their curves; remember the
        seeds whose running success reached the threshold (``candidates``)."""
        steps_per_update = self.cfg.run.steps_per_update
        scalars, self.candidates = [], []
        for s in seeds:
            plan, seed = self.plan(st, s), self.slots.seeds[s]
            tag = level_tag(seed, plan)
            rows, logged = count_level(st, s, out, steps_per_update, tag)
            scalars += logged
            for episodes, env_steps, running in rows:
                st.curves.append([seed, plan.level, plan.name, episodes, env_steps, running, s])
            if out.metrics is not None:
                scalars += learner_scalars(out.metrics, s, tag, st.level[s].env_steps)
            running = st.level[s].running
            if (running is not None and running >= self.level_cfg(st, s).threshold
                    and self.has_threshold(plan.option)):
                self.candidates.append(s)
        return scalars

    def has_threshold(self, option: int) -> bool:
        """A level can end at its threshold: an option's success lies in [0, 1]; the root's
        (option 0) unless it is a return on no known scale (CartPole's, tens, would pass
        0.8 at once): such a root level spends its whole budget instead."""
        return option != 0 or self.engine.root_has_threshold

    def budget_spent(self, st: TrainerState, s: int) -> bool:
        c, level = st.level[s], self.level_cfg(st, s)
        return c.episodes >= level.max_episodes_per_level or bool(
            level.max_steps_per_level and c.env_steps >= level.max_steps_per_level)

    def decide(self, st: TrainerState, seeds: list[int], controls: list[SeedControls],
               ends: Ends) -> list[Scalar]:
        """The seeds (of ``seeds``, this chunk's) whose level ends now: passed (marked
        ``reached``) or out of budget; the gate attempts' scalars."""
        passed, scalars = self.gate(st, controls)
        for s in passed:
            st.level[s].reached = True
        ends.levels = [s for s in seeds if s in passed or self.budget_spent(st, s)]
        return scalars

    def gate(self, st: TrainerState, controls: list[SeedControls]
             ) -> tuple[list[int], list[Scalar]]:
        """Seeds (of ``candidates``) whose level ends now: all of them without the gate;
        with it, those whose frozen policy passes a gate attempt (tried every
        ``gate_interval`` chunks, and once more when the budget is spent)."""
        candidates = self.candidates
        if not self.cfg.evaluation.gate or not candidates:
            return candidates, []
        due = [s for s in candidates
               if st.chunks >= st.level[s].gate_next or self.budget_spent(st, s)]
        if not due:
            return [], []
        # one vmapped call for all seeds; those not due are skipped (their results unused)
        result, compile_s = self.engine.gate(*self.gate_args(st, controls, due),
                                             place=self.slots.small)
        st.compile_seconds += compile_s
        result = dist.gather(result)
        passed, scalars = [], []
        for s in due:
            c, level = st.level[s], self.level_cfg(st, s)
            success = c.record_gate(result, s, st.chunks + self.cfg.evaluation.gate_interval)
            tag = level_tag(self.slots.seeds[s], self.plan(st, s))
            scalars += [Scalar(f"{tag}/gate_success", success, c.env_steps),
                        Scalar(f"{tag}/gate_uncalled", c.gate_uncalled, c.env_steps)]
            if success >= level.threshold:
                passed.append(s)
        return passed, scalars

    def gate_args(self, st: TrainerState, controls: list[SeedControls], due: list[int],
                  a=None):
        """``Engine.gate``'s arguments for a gate attempt of the ``due`` seeds (on the state
        ``a``; default the slots')."""
        a = self.slots.arrays if a is None else a
        # the attempt number varies the gate's episodes between attempts, deterministically
        keys = fold_in(a.keys, jnp.asarray(st.chunks, jnp.uint32))
        return (keys, a.state, a.bank, a.learned, [c.option for c in controls],
                [c.start for c in controls], [s in due for s in range(len(self.slots))],
                [c.threshold for c in controls])

    def gate_ahead(self, st: TrainerState, controls: list[SeedControls], ahead, a) -> None:
        """Compile the gate's program on ``ahead``'s thread (with the gate on), for the state
        ``a`` (or its shapes: ``smjax.train.ahead.arguments``)."""
        if self.cfg.evaluation.gate:
            make = lambda a: self.engine.gate_args(  # noqa: E731
                *self.gate_args(st, controls, [], a), place=self.slots.small)
            self.engine.episodes_ahead(arguments(make, a), self.cfg.evaluation.gate_envs, ahead)

    def finish(self, st: TrainerState, ends: Ends, options: list[int]) -> None:
        """Freeze the learners of the seeds whose level ended into their banks and record
        their levels; they move on to their next stage."""
        if not ends.levels:
            return
        freeze_learners(self.slots, ends.levels, options)
        for s in ends.levels:
            st.finish_level(s)


def freeze_learners(slots: Slots, seeds: list[int], options: list[int]) -> None:
    """Store these seeds' learner params in their banks at ``options[s]``."""
    a = slots.local()
    bank, learned = freeze(slots.mask(seeds), jnp.asarray(options, jnp.int32),
                           a.state.learner.params, a.bank, a.learned)
    slots.set(a.replace(bank=bank, learned=learned))
