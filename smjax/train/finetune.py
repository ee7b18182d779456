"""The fine-tuning phase: the learned hierarchy keeps learning without teleports.

Levels learn with help: while a level trains, every option it calls that is not learned
yet is teleported (or played by a scripted controller), and a level stops at 0.8 running
success measured in that world. Chained, the learned options compound (about 0.8 per
level), and the upper levels never saw what the *learned* lower options deliver: a
teleport lands in a different distribution of states. After the levels, fine-tuning runs
the learned hierarchy alone (no teleports; scripted leaf controllers still run, as in
evaluation) in whole-task episodes, and lets its options learn there.

How the options learn (``TrainConfig.finetune_mode``):

* joint (the default): every learned option learns at once, from every episode. Each has
  its own learner (``TrainArrays.joint``: [S, O, ...], warm-started from the bank), explores
  through its ``act``, and trains on its own record of every tick (``smjax.options.joint``)
  in ``Engine.joint_chunk``, its own compiled program. Seeds still at a level run the level
  chunk in the same loop iteration; each seed runs in one of the two.
* turns: one option learns at a time, top-down and then round again, warm-started from
  its frozen policy (``Agent.warm_start``), while the other options act frozen. Turns reuse
  the levels' compiled chunk (the option, teleports and episode continuation are traced per
  seed). A turn ends once its option's running success reaches
  ``finetune_option_threshold`` or after ``finetune_turn_episodes``; its policy then goes
  back into the bank, and the next turn's learner takes over the same episodes in flight
  (``TrainConfig.finetune_continue_episodes``). An option whose turn ended at that
  threshold rests for up to ``finetune_max_rest`` turns in a row (default 0: never).

Either way each option trains on its own decisions with its own reward (the root: the
environment's; a template: its F_o), in the states the learned hierarchy calls it from.
The phase starts with a gate: the levels' hierarchy is evaluated on fresh teleport-free
episodes (``final_success_before``), and a seed that already passes ``finetune_threshold``
there is not fine-tuned at all (``_pass_before``).
Whole-task episodes end by themselves, so the task's teleport-free running success is known
after every update: once it reaches ``finetune_threshold`` a gate (fresh episodes of the
hierarchy with the learners frozen in, no teleports) decides. The phase ends when the gate
passes, when the task success stops climbing (blocks of ``finetune_plateau_episodes``
whole-task episodes whose means rise by less than ``finetune_plateau_gain``), or after
``finetune_max_episodes``.

Where no gate passed, the phase hands back the better of two hierarchies: the fine-tuned
one is evaluated on fresh teleport-free episodes (counted as gate episodes) and, if it
scores below the levels' hierarchy (``final_success_before``), the levels' bank is put
back. Fine-tuning is not guaranteed to improve a hierarchy (DQN fine-tuning can wreck a
good one), so it never ends worse than the levels left it.
"""
from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from smjax.train import distributed as dist
from smjax.train.config import ConfigError
from smjax.train.seed_arrays import (
    NonFiniteError, all_finite, fold_in, freeze, local, select_seeds,
)


def next_turn(turn: int, order: list[str], turns: list[dict], rested: dict[str, int],
              threshold: float, max_rest: int) -> int:
    """The turn index after ``turn`` (its option: ``order[index % len(order)]``), skipping
    resting options; updates ``rested`` (template -> turns sat out in a row).

    An option rests while its last turn (in ``turns``, the phase's record) ended with
    running success >= ``threshold``, for at most ``max_rest`` turns in a row: then it
    plays again, so an option whose callers have moved on is checked where they now call
    it. Ends: each skip raises a counter that stops at ``max_rest``."""
    last = {t["template"]: t["running_success"] for t in turns}
    index = turn + 1
    while True:
        name = order[index % len(order)]
        success = last.get(name)
        if success is None or success < threshold or rested.get(name, 0) >= max_rest:
            rested[name] = 0
            return index
        rested[name] = rested.get(name, 0) + 1
        index += 1


@jax.jit
def bank_rows(bank, options: jax.Array):
    """Per seed (leading axis), the bank's params of option ``options[s]``."""
    rows = jnp.arange(options.shape[0])
    return jax.tree.map(lambda b: b[rows, options], bank)


@jax.jit
def store_learned(mask: jax.Array, learned: jax.Array, params, bank):
    """Per masked seed, ``params`` [S, O, ...] (a learner per option) stored in the bank at
    every learned option; the rest of the bank is kept."""
    keep = mask[:, None] & learned

    def pick(p, b):
        return jnp.where(keep.reshape(keep.shape + (1,) * (p.ndim - 2)), p, b)

    return jax.tree.map(pick, params, bank)


class FinetunePhase:
    """The trainer's fine-tuning steps (mixed into ``HierarchyTrainer``, whose state they
    use: ``state.finetune`` holds each seed's ``FinetuneCounters``)."""

    @property
    def finetune_level(self) -> int:
        """The level number fine-tuning's curve is recorded under (after the last level)."""
        return max(p.level for p in self.plans) + 1

    def _finetune_hp(self, hp: dict) -> dict:
        """``cfg.finetune_agent`` as the learner's per-slot hyper-parameter leaves."""
        unknown = sorted(set(self.cfg.finetune_agent) - set(hp))
        if unknown:
            raise ConfigError(f"config field 'finetune_agent' names {unknown}, which the "
                              f"{self.cfg.algo} learner does not read per turn; it reads "
                              f"{sorted(hp)}")
        return {k: jnp.full_like(hp[k], v) for k, v in self.cfg.finetune_agent.items()}

    def _account_task(self, stats, task, s: int) -> bool:
        """Count seed ``s``'s fine-tuning chunk (``task``: the task window's, per update);
        True if its teleport-free task success over the window reached the threshold."""
        cfg, rec, seed = self.cfg, self.state.finetune[s], self.seeds[s]
        for success, episodes in zip(stats.task_success[s], stats.task_episodes[s]):
            rec.add_to_block(success, episodes, cfg.finetune_plateau_episodes)
        rows = rec.count(stats.env_episodes[s], task[0][s], task[1][s],
                         cfg.num_envs * cfg.rollout_ticks)
        for episodes, env_steps, running in rows:
            self.state.curves.append([seed, self.finetune_level, "finetune", episodes,
                                      env_steps, running, s])
            if self._tb is not None and running is not None:
                self._tb.add_scalar(f"seed_{seed}/finetune/task_success", running, env_steps)
        return (rec.task_running is not None and rec.task_running >= cfg.finetune_threshold
                and self.engine.root_has_threshold)  # a raw return is no success rate

    def _phase_spent(self, s: int) -> bool:
        return self.state.finetune[s].episodes >= self.cfg.finetune_max_episodes

    def _candidate_bank(self, seeds: list[int]):
        """(bank, learned) with these seeds' learners frozen in at their options (joint:
        every learned option's learner at its own)."""
        a = self.arrays
        if self.joint:
            mask = self._place_small(self._mask(seeds))
            return store_learned(mask, a.learned, a.joint.learner.params, a.bank), a.learned
        mask, options = self._place_small((self._mask(seeds), self._options()))
        return freeze(mask, options, a.state.learner.params, a.bank, a.learned)

    def _accept_task(self, candidates: list[int]) -> list[int]:
        """Fine-tuning seeds (of ``candidates``) whose hierarchy, with the learner frozen in,
        passes a teleport-free gate at ``finetune_threshold`` (every ``gate_interval``
        chunks, and once more when the budget is spent; all candidates without the gate)."""
        st, cfg = self.state, self.cfg
        if not cfg.gate or not candidates:
            return candidates
        due = [s for s in candidates
               if st.chunks >= st.finetune[s].gate_next or self._phase_spent(s)]
        if not due:
            return []
        S = len(self.seeds)
        keys = fold_in(self.arrays.keys, jnp.asarray(st.chunks, jnp.uint32))
        bank, learned = self._candidate_bank(due)
        result, compile_s = self.engine.evaluate(
            keys, bank, learned, place=self._place_small,
            due=[s in due for s in range(S)], threshold=cfg.finetune_threshold)
        st.compile_seconds += compile_s
        result = dist.gather(result)
        return [s for s in due if st.finetune[s].record_gate(
            result, s, st.chunks + cfg.gate_interval) >= cfg.finetune_threshold]

    def _finetune_ends(self, passed: list[int]) -> tuple[list[int], list[int]]:
        """(seeds whose phase ends: passed or out of budget, seeds whose turn ends)."""
        st, cfg = self.state, self.cfg
        phase, turn = [], []
        for s in self._training():
            if not self._finetuning(s):
                continue
            running, rec = st.level[s].running, st.finetune[s]
            plateau = (cfg.finetune_plateau_episodes > 0
                       and rec.plateaued(cfg.finetune_plateau_gain))
            if s in passed or self._phase_spent(s) or plateau:
                phase.append(s)
                rec.reached = s in passed
                rec.stop = "gate" if s in passed else "plateau" if plateau else "budget"
            elif not self.joint and (
                    (running is not None and running >= cfg.finetune_option_threshold)
                    or st.level[s].episodes >= cfg.finetune_turn_episodes):
                turn.append(s)
        return phase, turn

    def _finish_turns(self, seeds: list[int], phase_ended: list[int]) -> None:
        """Freeze these seeds' learners back into the bank; the next turn, or done (the
        phase then hands back the better bank: ``_keep_better``)."""
        if not seeds:
            return
        st = self.state
        if self.joint:
            self._freeze_joint(seeds)
        else:
            self._freeze_learners(seeds)
        self._keep_better(phase_ended)
        for s in seeds:
            st.finetune[s].turns.append({"template": "joint" if self.joint else self._plan(s).name,
                                         "episodes": st.level[s].episodes,
                                         "running_success": st.level[s].running})
            if s in phase_ended:
                st.stage[s] += 1
            else:
                rec = st.finetune[s]
                rec.turn = next_turn(rec.turn, [p.name for p in self.ft_order], rec.turns,
                                     rec.rested, self.cfg.finetune_option_threshold,
                                     self.cfg.finetune_max_rest)
            st.started[s] = False

    # ---- joint fine-tuning (TrainConfig.finetune_mode "joint") ------------------------
    def _joint_tuning(self, s: int) -> bool:
        """Seed ``s`` fine-tunes all its options at once (``arrays.joint``)."""
        return self.joint and self._finetuning(s)

    def _option_gammas(self, s: int) -> list[float]:
        """Joint fine-tuning's discount per option for slot ``s``: the one the option's
        level trained it at (``levels[name]["gamma"]``), else the slot's: each option's
        values keep the horizon they were learned for (``smjax.options.joint``)."""
        level = {p.option: p.name for p in self.ft_order}
        return [self._level_gamma(level.get(o), s) for o in range(self.engine.h.num_options)]

    def _joint_chunk(self, seeds: list[int]):
        """Joint fine-tuning's compiled chunk for these seeds (the others keep their
        state); its stats and windows as ``_chunk``'s, each learned option's learner
        metrics to TensorBoard."""
        S, a, cfg = len(self.seeds), self.arrays, self.cfg
        weight = cfg.finetune_side_cost_weight if cfg.finetune_side_cost else 0.0
        sizes = [[cfg.success_window, cfg.success_window]] * S
        args = (a.joint, self._per_seed([s in seeds for s in range(S)], bool), a.learned,
                self._per_seed([weight] * S, jnp.float32),
                self._per_seed([self._option_gammas(s) for s in range(S)], jnp.float32),
                (a.window, a.task_window), self._per_seed(sizes, jnp.int32))
        if self._compiled_joint is None:
            t0 = time.perf_counter()
            self._compiled_joint = self.engine.compile("joint_chunk", self.engine.joint_chunk,
                                                       args, donate=(0,))
            self.state.compile_seconds += time.perf_counter() - t0
        state, stats, metrics, (window, task_window), windows = self._compiled_joint(*args)
        stats, windows = dist.gather((stats, windows))
        if not all_finite(state.learner.params):
            raise NonFiniteError(f"non-finite learner parameters in chunk {self.state.chunks} "
                                 f"(joint fine-tuning of seeds {[self.seeds[s] for s in seeds]})")
        self.arrays = a.replace(joint=state, window=window, task_window=task_window)
        if self.cfg.tensorboard:  # collectives: every process gathers, process 0 writes
            self._log_joint(dist.gather(metrics), np.asarray(dist.gather(a.learned)), seeds)
        return stats, windows

    def _log_joint(self, metrics: dict, learned: np.ndarray, seeds: list[int]) -> None:
        """TensorBoard: each learned option's learner metrics ([S, U, O]: the mean over the
        chunk's updates) under ``seed_S/finetune/joint/NAME/learner/``."""
        if self._tb is None:
            return
        # once per chunk, as ``_log_learner`` does (not per seed and option)
        means = {key: np.asarray(value, np.float64) for key, value in metrics.items()}
        for s in seeds:
            for o, name in enumerate(self.engine.h.option_names):
                if not learned[s, o]:
                    continue
                tag = f"seed_{self.seeds[s]}/finetune/joint/{name}/learner"
                for key, value in means.items():
                    if value.ndim == 3:  # [S, U, O]: one scalar per update and option
                        self._tb.add_scalar(f"{tag}/{key}", float(np.mean(value[s, :, o])),
                                            self.state.finetune[s].env_steps)

    def _freeze_joint(self, seeds: list[int]) -> None:
        """Store these seeds' learned options' joint learners in their banks."""
        a = jax.tree.map(local, self.arrays)
        bank = store_learned(self._mask(seeds), a.learned, a.joint.learner.params, a.bank)
        self.arrays = a.replace(bank=bank)
        self._place()

    def _evaluate_bank(self, seeds: list[int], fold: int) -> dict:
        """These seeds' hierarchies as the bank holds them, on fresh teleport-free episodes
        (``fold``: a key fold no gate uses; gates fold in the chunk count)."""
        S, a = len(self.seeds), self.arrays
        keys = fold_in(a.keys, jnp.asarray(fold, jnp.uint32))
        result, compile_s = self.engine.evaluate(
            keys, a.bank, a.learned, place=self._place_small,
            due=[s in seeds for s in range(S)])
        self.state.compile_seconds += compile_s
        return dist.gather(result)

    def _evaluate_before(self, seeds: list[int]) -> None:
        """final_success of these seeds' hierarchies as the levels left them; their banks
        are kept (``TrainArrays.levels_bank``) for ``_keep_better``."""
        if not seeds:
            return
        result = self._evaluate_bank(seeds, np.iinfo(np.uint32).max)
        a = jax.tree.map(local, self.arrays)
        self.arrays = a.replace(levels_bank=select_seeds(self._mask(seeds), a.bank, a.levels_bank))
        self._place()
        for s in seeds:
            self.state.finetune[s].success_before = float(result["success"][s])
            self.state.finetune[s].baseline = True
        self._pass_before(seeds, result)

    def _pass_before(self, seeds: list[int], result: dict) -> None:
        """The evaluation before the phase is also its first gate (the same fresh
        teleport-free episodes as ``_accept_task``'s): a seed whose levels' hierarchy already
        passes ``finetune_threshold`` has nothing to fine-tune, and its phase ends before it
        starts: fine-tuning a hierarchy that already passes can only cost env steps, and
        with DQN it can risk the hierarchy."""
        if not self.cfg.gate:
            return
        for s in seeds:
            rec = self.state.finetune[s]
            rec.gate_attempts += 1
            rec.gate_env_steps += int(result["env_steps"][s])
            rec.gate_success = rec.success_before
            if rec.success_before >= self.cfg.finetune_threshold:
                rec.reached, rec.stop, rec.kept = True, "gate", "levels"
                self.state.stage[s] += 1  # past the phase: nothing starts for it

    def _keep_better(self, seeds: list[int]) -> None:
        """Seeds whose phase ends: where no gate passed, evaluate the fine-tuned hierarchy
        and put the levels' bank back if it scored higher before fine-tuning."""
        recs = self.state.finetune
        for s in seeds:
            recs[s].kept = "fine-tuned"
        check = [s for s in seeds if not recs[s].reached and recs[s].baseline]
        if not check:
            return
        result = self._evaluate_bank(check, np.iinfo(np.uint32).max - 1)
        worse = []
        for s in check:
            recs[s].check_success = float(result["success"][s])
            recs[s].gate_env_steps += int(result["env_steps"][s])
            if recs[s].check_success < recs[s].success_before:
                recs[s].kept = "levels"
                worse.append(s)
        if worse:
            a = jax.tree.map(local, self.arrays)
            self.arrays = a.replace(bank=select_seeds(self._mask(worse), a.levels_bank, a.bank))
            self._place()
