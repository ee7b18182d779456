"""The fine-tuning stage: the learned hierarchy keeps learning without teleports.

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
there is not fine-tuned at all (``FinetuneStage.enter``).
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

import jax.numpy as jnp
import numpy as np

from smjax.train import distributed as dist
from smjax.train.config import TrainConfig
from smjax.train.finetune_ops import bank_rows, next_turn, store_learned
from smjax.train.levels import count_level, freeze_learners, level_tag
from smjax.train.plans import LevelPlan, finetune_order
from smjax.train.seed_arrays import fold_in, freeze, select_seeds
from smjax.train.slots import Slots
from smjax.train.stages import (
    ChunkOut, Ends, Scalar, SeedControls, SeedStatus, learner_scalars,
)
from smjax.train.state import TrainerState

# evaluation key folds no gate uses (gates fold in the chunk count)
BEFORE_FOLD = np.iinfo(np.uint32).max
CHECK_FOLD = np.iinfo(np.uint32).max - 1


class FinetuneStage:
    """Seeds fine-tuning (``st.stage[s] == len(plans)``: after every level), in turns or
    jointly (``joint``); ``state.finetune`` holds each seed's ``FinetuneCounters`` and, in
    turns, ``state.level`` the turn's."""

    def __init__(self, engine, cfg: TrainConfig, plans: list[LevelPlan], slots: Slots):
        self.engine, self.cfg, self.slots = engine, cfg, slots
        # fine-tuning's learner hyper-parameter leaves (``finetune_hp``), once a learner exists
        self.hp: dict = {}
        self.index = len(plans)
        self.order = finetune_order(engine.h, cfg)  # the turns' options, round and round
        self.joint = cfg.fine_tuning.mode == "joint"
        # the level number fine-tuning's curve is recorded under (after the last level)
        self.level = max(p.level for p in plans) + 1
        self.candidates: list[int] = []  # seeds whose task success reached the threshold

    def holds(self, st: TrainerState, s: int) -> bool:
        return st.stage[s] == self.index

    def plan(self, st: TrainerState, s: int) -> LevelPlan:
        """The option whose turn it is (joint: the root's, the first turn's)."""
        return self.order[st.finetune[s].turn % len(self.order)]

    def controls(self, st: TrainerState, s: int) -> SeedControls:
        """A turn's chunk: the learned hierarchy alone (no teleports), whole episodes."""
        plan = self.plan(st, s)
        level = self.cfg.for_level(plan.name)
        return SeedControls(
            option=plan.option, start=plan.start, teleport=False, keep_episodes=True,
            side_cost=self.cfg.fine_tuning.side_cost, gamma=self.slots.level_gamma(plan.name, s),
            window=level.success_window, task_window=self.cfg.success_window,
            threshold=level.threshold, joint=self.joint)

    def option_gammas(self, s: int) -> list[float]:
        """Joint fine-tuning's discount per option for slot ``s``: the one the option's
        level trained it at, else the slot's (``Slots.level_gamma``): each option's
        values keep the horizon they were learned for (``smjax.options.joint``)."""
        level = {p.option: p.name for p in self.order}
        return [self.slots.level_gamma(level.get(o), s)
                for o in range(self.engine.h.num_options)]

    def joint_controls(self) -> tuple[list, list, list]:
        """Joint fine-tuning's per-seed inputs for every seed: the side cost's weight, each
        option's discount, the learner's and the task's window sizes."""
        S, window = len(self.slots), self.cfg.success_window
        return ([self.cfg.fine_tuning.side_cost] * S, [self.option_gammas(s) for s in range(S)],
                [[window, window]] * S)

    def status(self, st: TrainerState, s: int) -> SeedStatus:
        c = st.level[s]
        return SeedStatus(where="FT", running=None, gate=None, task=st.finetune[s].task_running,
                          episodes=c.episodes, env_steps=c.env_steps,
                          by_steps=bool(self.cfg.for_level(self.plan(st, s).name)
                                        .max_steps_per_level))

    # ---- a chunk ---------------------------------------------------------------
    def account(self, st: TrainerState, seeds: list[int], out: ChunkOut) -> list[Scalar]:
        """Count the chunk toward these seeds' phase (the task's curve) and their turns'
        counters; remember the seeds whose task success reached the threshold."""
        steps_per_update = self.cfg.run.steps_per_update
        # joint learners' metrics at the phase's env steps before this chunk's
        scalars = self.joint_scalars(st, seeds, out)
        self.candidates = [s for s in seeds
                           if self.account_task(st, s, out, steps_per_update, scalars)]
        for s in seeds:
            seed, plan = self.slots.seeds[s], self.plan(st, s)
            scalars += count_level(st, s, out, steps_per_update, level_tag(seed, plan))[1]
        if out.metrics is not None and not self.joint:
            scalars += [x for s in seeds for x in learner_scalars(
                out.metrics, s, f"seed_{self.slots.seeds[s]}/finetune/{self.plan(st, s).name}",
                st.finetune[s].env_steps)]
        return scalars

    def account_task(self, st: TrainerState, s: int, out: ChunkOut, steps_per_update: int,
                     scalars: list[Scalar]) -> bool:
        """Count seed ``s``'s chunk toward its phase (the task window's batches); True if
        its teleport-free task success over the window reached the threshold."""
        cfg, rec, seed, task = self.cfg, st.finetune[s], self.slots.seeds[s], out.windows[1]
        for success, episodes in zip(out.stats.task_success[s], out.stats.task_episodes[s]):
            rec.add_to_block(success, episodes, cfg.fine_tuning.plateau_episodes)
        rows = rec.count(out.stats.env_episodes[s], task[0][s], task[1][s], steps_per_update)
        for episodes, env_steps, running in rows:
            st.curves.append([seed, self.level, "finetune", episodes, env_steps, running, s])
            if running is not None:
                scalars.append(Scalar(f"seed_{seed}/finetune/task_success", running, env_steps))
        return (rec.task_running is not None and rec.task_running >= cfg.fine_tuning.threshold
                and self.engine.root_has_threshold)  # a raw return is no success rate

    def joint_scalars(self, st: TrainerState, seeds: list[int], out: ChunkOut) -> list[Scalar]:
        """Joint: each learned option's learner metrics ({name: [S, U, O]}, the mean over
        the chunk's updates) under ``seed_S/finetune/joint/NAME/learner/``."""
        if out.joint_metrics is None:
            return []
        scalars = []
        for s in seeds:
            for o, name in enumerate(self.engine.h.option_names):
                if not out.joint_learned[s, o]:
                    continue
                tag = f"seed_{self.slots.seeds[s]}/finetune/joint/{name}/learner"
                scalars += [Scalar(f"{tag}/{key}", float(np.mean(value[s, :, o])),
                                   st.finetune[s].env_steps)
                            for key, value in out.joint_metrics.items() if value.ndim == 3]
        return scalars

    def spent(self, st: TrainerState, s: int) -> bool:
        return st.finetune[s].episodes >= self.cfg.fine_tuning.max_episodes

    def decide(self, st: TrainerState, seeds: list[int], controls: list[SeedControls],
               ends: Ends) -> list[Scalar]:
        """Seeds whose phase ends (passed, out of budget or on a plateau) and, in turns,
        whose turn ends (its option's running success or its episodes reached their
        bound)."""
        cfg, passed = self.cfg, self.gate(st, controls)
        for s in seeds:
            running, rec = st.level[s].running, st.finetune[s]
            plateau = (cfg.fine_tuning.plateau_episodes > 0
                       and rec.plateaued(cfg.fine_tuning.plateau_gain))
            if s in passed or self.spent(st, s) or plateau:
                ends.phases.append(s)
                rec.reached = s in passed
                rec.stop = "gate" if s in passed else "plateau" if plateau else "budget"
            elif not self.joint and (
                    (running is not None and running >= cfg.fine_tuning.option_threshold)
                    or st.level[s].episodes >= cfg.fine_tuning.turn_episodes):
                ends.turns.append(s)
        return []

    def gate(self, st: TrainerState, controls: list[SeedControls]) -> list[int]:
        """Seeds (of ``candidates``) whose hierarchy, with the learner frozen in, passes a
        teleport-free gate at ``finetune_threshold`` (every ``gate_interval`` chunks, and
        once more when the budget is spent; all candidates without the gate)."""
        cfg, candidates = self.cfg, self.candidates
        if not cfg.evaluation.gate or not candidates:
            return candidates
        due = [s for s in candidates if st.chunks >= st.finetune[s].gate_next or self.spent(st, s)]
        if not due:
            return []
        keys = fold_in(self.slots.arrays.keys, jnp.asarray(st.chunks, jnp.uint32))
        bank, learned = self.candidate_bank(due, [c.option for c in controls])
        result, compile_s = self.engine.evaluate(
            keys, bank, learned, place=self.slots.small,
            due=[s in due for s in range(len(self.slots))], threshold=cfg.fine_tuning.threshold)
        st.compile_seconds += compile_s
        result = dist.gather(result)
        return [s for s in due if st.finetune[s].record_gate(
            result, s, st.chunks + cfg.evaluation.gate_interval) >= cfg.fine_tuning.threshold]

    def candidate_bank(self, seeds: list[int], options: list[int]):
        """(bank, learned) with these seeds' learners frozen in at their options (joint:
        every learned option's learner at its own)."""
        a, slots = self.slots.arrays, self.slots
        if self.joint:
            mask = slots.small(slots.mask(seeds))
            return store_learned(mask, a.learned, a.joint.learner.params, a.bank), a.learned
        mask, options = slots.small((slots.mask(seeds), jnp.asarray(options, jnp.int32)))
        return freeze(mask, options, a.state.learner.params, a.bank, a.learned)

    # ---- the phase's boundaries --------------------------------------------------
    def enter(self, st: TrainerState, seeds: list[int]) -> None:
        """Seeds that finished their levels: final_success of their hierarchies as the
        levels left them, their banks kept (``TrainArrays.levels_bank``) for ``keep_better``.
        That evaluation is also the phase's first gate (the same fresh teleport-free
        episodes as ``gate``'s): a seed whose levels' hierarchy already passes
        ``finetune_threshold`` has nothing to fine-tune, and its phase ends before it
        starts: fine-tuning a hierarchy that already passes can only cost env steps, and
        with DQN it can risk the hierarchy."""
        if not seeds:
            return
        result = self.evaluate_bank(st, seeds, BEFORE_FOLD)
        slots = self.slots
        a = slots.local()
        slots.set(a.replace(levels_bank=select_seeds(slots.mask(seeds), a.bank, a.levels_bank)))
        for s in seeds:
            rec = st.finetune[s]
            rec.success_before, rec.baseline = float(result["success"][s]), True
            if not self.cfg.evaluation.gate:
                continue
            rec.gate_attempts += 1
            rec.gate_env_steps += int(result["env_steps"][s])
            rec.gate_success = rec.success_before
            if rec.success_before >= self.cfg.fine_tuning.threshold:
                rec.reached, rec.stop, rec.kept = True, "gate", "levels"
                st.stage[s] += 1  # past the phase: nothing starts for it

    def evaluate_bank(self, st: TrainerState, seeds: list[int], fold: int) -> dict:
        """These seeds' hierarchies as the bank holds them, on fresh teleport-free episodes
        (``fold``: a key fold no gate uses)."""
        a = self.slots.arrays
        keys = fold_in(a.keys, jnp.asarray(fold, jnp.uint32))
        result, compile_s = self.engine.evaluate(
            keys, a.bank, a.learned, place=self.slots.small,
            due=[s in seeds for s in range(len(self.slots))])
        st.compile_seconds += compile_s
        return dist.gather(result)

    def finish(self, st: TrainerState, ends: Ends, options: list[int]) -> None:
        """Seeds that finished their levels enter the phase (``enter``); seeds whose turn
        or phase ended freeze their learners back into their banks (``options``: per
        seed, the option whose turn it was), then go on to the next turn, or are done
        (the phase hands back the better bank: ``keep_better``)."""
        self.enter(st, [s for s in ends.levels if self.holds(st, s)])
        seeds = ends.turns + ends.phases
        if not seeds:
            return
        slots = self.slots
        if self.joint:
            a = slots.local()
            slots.set(a.replace(bank=store_learned(slots.mask(seeds), a.learned,
                                                   a.joint.learner.params, a.bank)))
        else:
            freeze_learners(slots, seeds, options)
        self.keep_better(st, ends.phases)
        for s in seeds:
            rec = st.finetune[s]
            rec.turns.append({"template": "joint" if self.joint else self.plan(st, s).name,
                              "episodes": st.level[s].episodes,
                              "running_success": st.level[s].running})
            if s in ends.phases:
                st.stage[s] += 1
            else:
                rec.turn = next_turn(rec.turn, [p.name for p in self.order], rec.turns,
                                     rec.rested, self.cfg.fine_tuning.option_threshold,
                                     self.cfg.fine_tuning.max_rest)
            st.started[s] = False

    def keep_better(self, st: TrainerState, seeds: list[int]) -> None:
        """Seeds whose phase ends: where no gate passed, evaluate the fine-tuned hierarchy
        and put the levels' bank back if it scored higher before fine-tuning."""
        recs = st.finetune
        for s in seeds:
            recs[s].kept = "fine-tuned"
        check = [s for s in seeds if not recs[s].reached and recs[s].baseline]
        if not check:
            return
        result = self.evaluate_bank(st, check, CHECK_FOLD)
        worse = []
        for s in check:
            recs[s].check_success = float(result["success"][s])
            recs[s].gate_env_steps += int(result["env_steps"][s])
            if recs[s].check_success < recs[s].success_before:
                recs[s].kept = "levels"
                worse.append(s)
        if worse:
            a = self.slots.local()
            self.slots.set(a.replace(bank=select_seeds(self.slots.mask(worse), a.levels_bank,
                                                       a.bank)))

    def start(self, st: TrainerState, seeds: list[int], fresh, arrays, k_reset, options):
        """These seeds' next turn (joint: the phase): ``fresh``, the new learners and
        environments of every seed (a ``SeedState``), and ``arrays`` as they will be, with
        these seeds' learners continuing from the bank (joint: one per option, in
        ``arrays.joint``) and, from a seed's second turn on, its episodes in flight going
        on (``finetune_continue_episodes``)."""
        learner, mask = fresh.learner, self.slots.mask(seeds)
        if self.joint:
            joint = self.engine.joint_state(learner.replace(hp={**learner.hp, **self.hp}),
                                            arrays.bank, k_reset, fresh.key)
            arrays = arrays.replace(joint=select_seeds(mask, joint, arrays.joint))
        else:
            warm = self.engine.warm_start(learner, bank_rows(arrays.bank,
                                                             jnp.asarray(options, jnp.int32)))
            fresh = fresh._replace(learner=select_seeds(
                mask, warm.replace(hp={**warm.hp, **self.hp}), learner))
        go_on = [s for s in seeds
                 if self.cfg.fine_tuning.continue_episodes and st.finetune[s].turns]
        if go_on:
            carry = select_seeds(self.slots.mask(go_on),
                                 self.engine.hand_over(arrays.state.carry), fresh.carry)
            fresh = fresh._replace(carry=carry)
        return fresh, arrays
