"""The fine-tuning phase: the learned hierarchy keeps learning without teleports.

Levels learn with help: while a level trains, every option it calls that is not learned
yet is teleported (or played by a scripted controller), and a level stops at 0.8 running
success measured in that world. Chained, the learned options compound (about 0.8 per
level), and the upper levels never saw what the *learned* lower options deliver: a
teleport lands in a different distribution of states. After the levels, fine-tuning runs
the learned hierarchy alone (no teleports; scripted leaf controllers still run, as in
evaluation) in whole-task episodes, and lets its options learn there.

One option learns at a time, in turns, top-down and then round again: the option's
learner is warm-started from its frozen policy (``Agent.warm_start``) and trains on its
own decisions with its own reward (the root: the environment's; a template: its F_o),
in the states the learned hierarchy actually calls it from, while the other options act
frozen. Turns reuse the levels' compiled chunk (the option, teleports and episode
continuation are traced per seed), so fine-tuning compiles nothing new and an update
costs what a level's does. A turn ends once its option's running success reaches
``finetune_option_threshold`` or after ``finetune_turn_episodes``; its policy then goes
back into the bank. Whole-task episodes end by themselves in every turn, so the task's
teleport-free running success is known after every update: once it reaches
``finetune_threshold`` a gate (fresh episodes of the hierarchy with the learner frozen
in, no teleports) decides, and the phase ends when it passes or after
``finetune_max_episodes``.
"""
from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from smjax.train import distributed as dist
from smjax.train.seed_arrays import fold_in, freeze

# a seed's fine-tuning bookkeeping (host state, checkpointed), and its start values
FINETUNE_COUNTERS: dict[str, Any] = {
    "turn": 0,               # turns started (the option is the turn's, round robin)
    "episodes": 0,           # environment episodes of the phase's training chunks
    "env_steps": 0,
    "task_history": None,    # [[summed success, episodes], ...] of whole-task episodes
    "task_running": None,    # teleport-free task success over the last success_window
    "gate_success": None,    # the last gate's success
    "gate_attempts": 0,
    "gate_env_steps": 0,
    "gate_next": 0,          # first chunk at which the next gate may run
    "reached": False,        # a gate passed
    "success_before": None,  # final_success of the hierarchy as the levels left it
    "turns": None,           # [{"template", "episodes", "running_success"}, ...]
}


_LISTS = ("task_history", "turns")


def new_record(num_seeds: int) -> dict:
    """Per-seed fine-tuning counters, as host state."""
    return {k: [[] for _ in range(num_seeds)] if k in _LISTS else [v] * num_seeds
            for k, v in FINETUNE_COUNTERS.items()}


def append_window(history: list, total: float, count: int, window: int) -> float | None:
    """Add a batch of ``count`` episodes whose successes sum to ``total`` to ``history``
    (trimmed in place to what the window needs); the mean success over the last
    ``window`` episodes (None: fewer so far)."""
    if count:
        history.append([total, count])
    total, seen, keep = 0.0, 0, 0
    for s, c in reversed(history):
        total, seen, keep = total + s, seen + c, keep + 1
        if seen >= window:
            break
    del history[:len(history) - keep]
    return total / seen if seen >= window else None


def record_gate(counters: dict, s: int, result: dict, next_chunk: int) -> float:
    """Count seed ``s``'s gate attempt (``result``: the episodes program's, gathered) in its
    ``gate_*`` counters; its success."""
    success = float(result["success"][s])
    counters["gate_success"][s] = success
    counters["gate_attempts"][s] += 1
    counters["gate_env_steps"][s] += int(result["env_steps"][s])
    counters["gate_next"][s] = next_chunk
    return success


@jax.jit
def bank_rows(bank, options: jax.Array):
    """Per seed (leading axis), the bank's params of option ``options[s]``."""
    rows = jnp.arange(options.shape[0])
    return jax.tree.map(lambda b: b[rows, options], bank)


class FinetunePhase:
    """The trainer's fine-tuning steps (mixed into ``HierarchyTrainer``, whose state they
    use: ``host["finetune"]`` holds the per-seed counters of ``FINETUNE_COUNTERS``)."""

    @property
    def finetune_level(self) -> int:
        """The level number fine-tuning's curve is recorded under (after the last level)."""
        return max(p.level for p in self.plans) + 1

    def _account_task(self, stats, s: int) -> bool:
        """Count seed ``s``'s fine-tuning chunk; True if its teleport-free task success
        over the window reached the threshold."""
        host, cfg, rec = self.host, self.cfg, self.host["finetune"]
        for u in range(cfg.updates_per_chunk):
            rec["episodes"][s] += int(stats.env_episodes[s, u])
            rec["env_steps"][s] += cfg.num_envs * cfg.rollout_ticks
            rec["task_running"][s] = append_window(
                rec["task_history"][s], float(stats.task_success[s, u]),
                int(stats.task_episodes[s, u]), cfg.success_window)
            host["curves"].append([self.seeds[s], self.finetune_level, "finetune",
                                   rec["episodes"][s], rec["env_steps"][s],
                                   rec["task_running"][s], s])
            if self._tb is not None and rec["task_running"][s] is not None:
                self._tb.add_scalar(f"seed_{self.seeds[s]}/finetune/task_success",
                                    rec["task_running"][s], rec["env_steps"][s])
        run = rec["task_running"][s]
        return run is not None and run >= cfg.finetune_threshold

    def _phase_spent(self, s: int) -> bool:
        return self.host["finetune"]["episodes"][s] >= self.cfg.finetune_max_episodes

    def _candidate_bank(self, seeds: list[int]):
        """(bank, learned) with these seeds' learners frozen in at their options."""
        options = [self._plan(s).option for s in range(len(self.seeds))]
        mask, options = self._place_small((self._mask(seeds), jnp.asarray(options, jnp.int32)))
        return freeze(mask, options, self.arrays["state"].learner.params,
                      self.arrays["bank"], self.arrays["learned"])

    def _accept_task(self, candidates: list[int]) -> list[int]:
        """Fine-tuning seeds (of ``candidates``) whose hierarchy, with the learner frozen in,
        passes a teleport-free gate at ``finetune_threshold`` (every ``gate_interval``
        chunks, and once more when the budget is spent; all candidates without the gate)."""
        host, cfg, rec = self.host, self.cfg, self.host["finetune"]
        if not cfg.gate or not candidates:
            return candidates
        due = [s for s in candidates
               if host["chunks"] >= rec["gate_next"][s] or self._phase_spent(s)]
        if not due:
            return []
        S = len(self.seeds)
        keys = fold_in(self.arrays["keys"], jnp.asarray(host["chunks"], jnp.uint32))
        bank, learned = self._candidate_bank(due)
        result, compile_s = self.engine.evaluate(
            keys, bank, learned, place=self._place_small,
            due=[s in due for s in range(S)], threshold=cfg.finetune_threshold)
        host["compile_seconds"] += compile_s
        result = dist.gather(result)
        return [s for s in due if record_gate(rec, s, result, host["chunks"] + cfg.gate_interval)
                >= cfg.finetune_threshold]

    def _finetune_ends(self, passed: list[int]) -> tuple[list[int], list[int]]:
        """(seeds whose phase ends: passed or out of budget, seeds whose turn ends)."""
        host, cfg, rec = self.host, self.cfg, self.host["finetune"]
        phase, turn = [], []
        for s in self._training():
            if not self._finetuning(s):
                continue
            running = host["running"][s]
            if s in passed or self._phase_spent(s):
                phase.append(s)
                rec["reached"][s] = s in passed
            elif ((running is not None and running >= cfg.finetune_option_threshold)
                  or host["episodes"][s] >= cfg.finetune_turn_episodes):
                turn.append(s)
        return phase, turn

    def _finish_turns(self, seeds: list[int], phase_ended: list[int]) -> None:
        """Freeze these seeds' learners back into the bank; the next turn, or done."""
        if not seeds:
            return
        host, rec = self.host, self.host["finetune"]
        self._freeze_learners(seeds)
        for s in seeds:
            rec["turns"][s].append({"template": self._plan(s).name,
                                    "episodes": host["episodes"][s],
                                    "running_success": host["running"][s]})
            if s in phase_ended:
                host["stage"][s] += 1
            else:
                rec["turn"][s] += 1
            host["started"][s] = False

    def _evaluate_before(self, seeds: list[int]) -> None:
        """final_success of these seeds' hierarchies as the levels left them."""
        if not seeds:
            return
        S = len(self.seeds)
        # a fold no gate uses (gates fold in the chunk count)
        keys = fold_in(self.arrays["keys"], jnp.asarray(np.iinfo(np.uint32).max, jnp.uint32))
        result, compile_s = self.engine.evaluate(
            keys, self.arrays["bank"], self.arrays["learned"],
            place=self._place_small, due=[s in seeds for s in range(S)])
        self.host["compile_seconds"] += compile_s
        result = dist.gather(result)
        for s in seeds:
            self.host["finetune"]["success_before"][s] = float(result["success"][s])
