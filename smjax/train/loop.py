"""The host loop shared by top-down, bottom-up and flat training.

It runs compiled chunks (``Engine.chunk``) and, between them, hands each chunk's
statistics to the seeds' counters, decides (a seed's running success against the
threshold, gates, the end of a level or of a fine-tuning turn), draws progress, records
curves and writes checkpoints; it never steps an environment itself. All seeds train together in
one compiled program, each at its own level: the option being trained and the option
episodes start from are per-seed traced values, so a seed that finishes a level starts
the next one in the next chunk instead of waiting for the slowest seed (only a seed that
has finished every level is masked). A seed's numbers do not depend on the other seeds.
Everything the loop knows lives in ``arrays`` (device state, ``TrainArrays``, with the
running-success windows) and ``state`` (host counters, ``TrainerState``; both in
:mod:`smjax.train.state`): exactly what a checkpoint holds, so a resumed run continues bit for bit.
The trainer's level steps (counting, budgets, the gate) are mixed in from
:mod:`smjax.train.levels`, its fine-tuning steps from :mod:`smjax.train.finetune`.
"""
from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.timeline import TIMELINE
from smjax.train import checkpoint as ckpt
from smjax.train import finetune as ft
from smjax.train.seed_arrays import (  # noqa: F401 - NonFiniteError re-exported
    NonFiniteError, all_finite, local, select_seeds, split_seeds,
)
from smjax.train import distributed as dist
from smjax.train.config import RUN_SETTINGS, TrainConfig
from smjax.train.engine import EVAL_TEMPERATURES, Engine, SeedState
from smjax.train.levels import LevelPhase
from smjax.train.restorable import check_restorable
from smjax.train.plans import LevelPlan, check_joint_learner, finetune_order
from smjax.train.progress import Progress
from smjax.train.sharding import seed_sharding, state_shardings, training_mesh
from smjax.train.state import SuccessWindow, TrainArrays, TrainerState


# 2: learner states carry their hyper-parameters (state.hp); 3: success windows are arrays;
# 4: the levels' bank (fine-tuning hands back the better hierarchy); 5: every step carries
# a manifest of checksums (the arrays are laid out as in 4)
CHECKPOINT_FORMAT = 5


class HierarchyTrainer(LevelPhase, ft.FinetunePhase):
    """Trains every planned level for all seeds, each seed at its own pace; resumable."""

    def __init__(self, engine: Engine, plans: list[LevelPlan], seeds: list[int], *,
                 out_dir=None, progress: bool = True, run_meta: dict | None = None,
                 hp: dict | None = None, gamma: list[float] | None = None):
        """``seeds``: one per slot (a sweep repeats them, once per point); ``hp``: per slot,
        the learner's sweepable hyper-parameters that differ from its config, ``gamma``:
        per slot, the discount (a sweep; default ``cfg.gamma``)."""
        self.engine, self.plans, self.seeds = engine, plans, list(seeds)
        self.gamma = list(gamma) if gamma is not None else [engine.cfg.gamma] * len(self.seeds)
        self.slot_hp = {k: jnp.asarray(v, jnp.float32) for k, v in (hp or {}).items()}
        self.cfg = engine.cfg
        self.cfg.check_level_names([p.name for p in plans])
        # after the levels, a seed fine-tunes (one stage more) unless it is off
        self.ft_order = finetune_order(engine.h, self.cfg)
        check_joint_learner(engine.h, self.cfg, engine.agent)
        self.joint = bool(self.ft_order) and self.cfg.finetune_mode == "joint"
        self.num_stages = len(plans) + bool(self.ft_order)
        self.out_dir = out_dir
        self.writer = dist.is_writer()  # process 0: the only one that writes files or draws bars
        self.progress = progress and self.writer
        self.run_meta = run_meta or {}
        S = len(self.seeds)
        keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(self.seeds, jnp.uint32))
        keys, k_init, k_reset = split_seeds(keys, 3)
        learner = self._init_learner(k_init)
        self.finetune_hp = self._finetune_hp(learner.hp)
        bank = engine.new_bank(learner)
        self.arrays = TrainArrays(
            bank=bank, keys=keys,
            learned=jnp.zeros((S, engine.h.num_options), bool),
            state=SeedState(engine.reset(k_reset, jnp.zeros((S,), jnp.int32)), learner, keys),
            **SuccessWindow.pair(S, self.cfg.window_slots),
            levels_bank=bank if self.ft_order else None,  # arrays are immutable: no copy
            joint=(engine.joint_state(learner, bank, k_reset, keys) if self.joint else None))
        self.state = TrainerState.new(plans, S)
        self._compiled = self._compiled_joint = None
        self._last_save = time.perf_counter()
        self.mesh = training_mesh(S, self.cfg.num_envs)
        self._place()
        self._tb = None
        if self.cfg.tensorboard and out_dir is not None and self.writer:
            from tensorboardX import SummaryWriter

            self._tb = SummaryWriter(str(Path(out_dir) / "tensorboard"))

    def _place(self) -> None:
        """Put the training state on the mesh (seed axis, then environment axis)."""
        if self.mesh is None:
            return
        a = self.arrays
        shardings = seed_sharding(self.mesh, a).replace(state=state_shardings(self.mesh, a.state))
        self.arrays = dist.place(a, shardings)

    def _place_small(self, tree):
        """Small per-call inputs (flags, masks) on the mesh: with several processes every
        input of a compiled program must be a global array."""
        if self.mesh is None:
            return tree
        return dist.place(tree, seed_sharding(self.mesh, tree))

    # ---- checkpoints -------------------------------------------------------------
    def save(self) -> None:
        """Checkpoint (collective with several processes: all gather, process 0 writes)."""
        if self.out_dir is None:
            return
        # the settings a resume starts from unless told otherwise (not the run's identity)
        settings = {k: getattr(self.cfg, k) for k in RUN_SETTINGS}
        # trained: every stage is done, so a resume only evaluates and writes results
        meta = {"host": self.state.to_json(), "run": self.run_meta, "settings": settings,
                "format": CHECKPOINT_FORMAT, "trained": not self._training()}
        arrays = dist.gather(self.arrays) if dist.is_multiprocess() else self.arrays
        if self.writer:
            ckpt.save_checkpoint(self.out_dir, self.state.chunks, arrays, meta)
        self._last_save = time.perf_counter()

    def restore(self, step: str | None = None, checked: tuple[dict, int] | None = None) -> bool:
        """Resume from process 0's checkpoint (its latest, or ``step``; formats 2 and 3 are
        migrated), verified against its manifest and the plan; the same on every process.
        ``checked``: what ``check_restorable`` returned for that checkpoint, where the caller
        checked it before building this trainer (its files are not hashed twice)."""
        if self.out_dir is None:
            return False
        if checked is None:
            checked = check_restorable(self.out_dir, step, len(self.seeds), self.num_stages,
                                       CHECKPOINT_FORMAT)
        if checked is None:
            return False
        info, version = checked
        like = self.arrays.as_stored(version)
        if dist.is_multiprocess():
            like = jax.tree.map(lambda x: np.zeros(x.shape, x.dtype), like)
            loaded = (ckpt.load_arrays(self.out_dir, like, step, verified=True) if self.writer
                      else like)
            loaded = jax.tree.map(jnp.asarray, dist.broadcast(loaded))
        else:
            loaded = ckpt.load_arrays(self.out_dir, like, step, verified=True)
        self.arrays = loaded.migrated(info["meta"]["host"], self.cfg.window_slots,
                                      levels_bank=self.arrays.levels_bank is not None)
        self.state = TrainerState.from_json(info["meta"]["host"])
        self._place()
        return True

    # ---- the loop ------------------------------------------------------------------
    def run(self) -> dict:
        st = self.state
        t_start = time.perf_counter() - st.wall_seconds
        self._timed("start levels (learner init, env reset)", self._start_levels,
                    [s for s in self._training() if not st.started[s]])
        bar = Progress(self) if self.progress else None
        while self._training():
            t0 = time.perf_counter()
            stats, windows, metrics = self._timed("training chunks", self._chunk)
            dt = time.perf_counter() - t0
            candidates, task_candidates = self._account(stats, windows)
            self._log_learner(metrics)
            st.chunks += 1
            passed = self._timed("gates", self._accept, candidates)
            task_passed = self._timed("gates", self._accept_task, task_candidates)
            ended = [s for s in self._training() if not self._finetuning(s)
                     and (s in passed or self._budget_spent(self._level_cfg(s), s))]
            for s in passed:
                st.level[s].reached = True
            phase_ended, turn_ended = self._finetune_ends(task_passed)
            st.wall_seconds = time.perf_counter() - t_start
            if ended or phase_ended or turn_ended:
                self._finish_levels(ended)
                self._finish_turns(turn_ended + phase_ended, phase_ended)
                # start the next levels before checkpointing: the checkpoint then holds their
                # fresh learners (an empty replay buffer compresses to nothing), not the
                # finished ones
                self._start_levels([s for s in ended + turn_ended
                                    if st.stage[s] < self.num_stages])
            if bar is not None:
                bar.draw(dt)
            if self.out_dir is not None and (ended or phase_ended or turn_ended
                                             or self._save_due()):
                with TIMELINE.span("checkpoint writes"):
                    self.save()
        if bar is not None:
            bar.close()
        return self._timed("evaluation", self._evaluate, t_start)

    def _timed(self, label: str, fn, *args):
        """``fn(*args)``, its seconds on the timeline under ``label`` and the compiling
        inside it under ``compile: label`` (apart, so the two never overlap)."""
        compiled, began = self.state.compile_seconds, TIMELINE.now()
        out = fn(*args)
        compiling = self.state.compile_seconds - compiled
        TIMELINE.add(label, began, TIMELINE.now() - began - compiling)
        if compiling:
            TIMELINE.add(f"compile: {label}", began, compiling)
        return out

    def _training(self) -> list[int]:
        """Seeds that still have a level to train (or are fine-tuning)."""
        return [s for s, i in enumerate(self.state.stage) if i < self.num_stages]

    def _finetuning(self, s: int) -> bool:
        return bool(self.ft_order) and self.state.stage[s] == len(self.plans)

    def _plan(self, s: int) -> LevelPlan:
        """The level a seed trains, or the option whose turn it is in fine-tuning."""
        if self._finetuning(s):
            turn = self.state.finetune[s].turn
            return self.ft_order[turn % len(self.ft_order)]
        return self.plans[min(self.state.stage[s], len(self.plans) - 1)]

    def _level_cfg(self, s: int) -> TrainConfig:
        return self.cfg.for_level(self._plan(s).name)

    def _gamma(self, s: int) -> float:
        """A slot's discount at the level it trains (``_level_gamma``)."""
        return self._level_gamma(self._plan(s).name, s)

    def _level_gamma(self, name: str | None, s: int) -> float:
        """Level ``name``'s own discount (``levels[name]["gamma"]``), else slot ``s``'s
        (``cfg.gamma``, or its sweep point's)."""
        return self.cfg.levels.get(name, {}).get("gamma", self.gamma[s])

    def _per_seed(self, values, dtype) -> jax.Array:
        return self._place_small(jnp.asarray(values, dtype))

    def _mask(self, seeds: list[int]) -> jax.Array:
        return jnp.asarray([s in seeds for s in range(len(self.seeds))])

    def _options(self) -> jax.Array:
        """Per seed, the option it trains."""
        return jnp.asarray([self._plan(s).option for s in range(len(self.seeds))], jnp.int32)

    def _chunk(self):
        """One compiled chunk for every seed at its own level (and joint fine-tuning's for
        the seeds in it: ``_joint_chunk``); its stats and windows [S, U], and the
        learner's update metrics [S, U] (None unless TensorBoard is on)."""
        joint = [s for s in self._training() if self._joint_tuning(s)]
        out = self._level_chunk(joint) if len(joint) < len(self._training()) else None
        if not joint:
            return out
        stats, windows = self._joint_chunk(joint)
        if out is None:
            return stats, windows, None
        # a seed's rows are zero in the program it did not run in
        add = lambda x, y: x + y  # noqa: E731
        return (jax.tree.map(add, out[0], stats), jax.tree.map(add, out[1], windows), out[2])

    def _level_chunk(self, skip: list[int]):
        """``_chunk``'s compiled chunk for the seeds at a level or turn (not ``skip``)."""
        S, a = len(self.seeds), self.arrays
        active = self._per_seed([i < self.num_stages and s not in skip
                                 for s, i in enumerate(self.state.stage)], bool)
        learner = self._place_small(self._options())
        start = self._per_seed([self._plan(s).start for s in range(S)], jnp.int32)
        # levels: teleports on; fine-tuning: the learned hierarchy alone, whole episodes
        tuning = [self._finetuning(s) for s in range(S)]
        teleport = self._per_seed([not t for t in tuning], bool)
        keep = self._per_seed([t or self.cfg.continue_episodes for t in tuning], bool)
        weight = self.cfg.finetune_side_cost_weight if self.cfg.finetune_side_cost else 0.0
        side_cost = self._per_seed([weight if t else self.cfg.level_side_cost_weight
                                    for t in tuning], jnp.float32)
        gamma = self._per_seed([self._gamma(s) for s in range(S)], jnp.float32)
        # the windows' sizes: the level's (or turn's option's), the task's (0: not fine-tuning)
        sizes = self._per_seed([[self._level_cfg(s).success_window, self.cfg.success_window * t]
                                for s, t in enumerate(tuning)], jnp.int32)
        args = (a.state, active, a.bank, a.learned, learner, start, teleport, keep, side_cost,
                gamma, (a.window, a.task_window), sizes)
        if self._compiled is None:  # one compile serves every level (ids are traced)
            t0 = time.perf_counter()
            self._compiled = self.engine.compile("chunk", self.engine.chunk, args, donate=(0,))
            self.state.compile_seconds += time.perf_counter() - t0
        state, stats, metrics, (window, task_window), windows = self._compiled(*args)
        stats, windows = dist.gather((stats, windows))  # [S, U, ...], the same on every process
        # a collective: every process gathers when TensorBoard is on (only process 0 writes)
        metrics = dist.gather(metrics) if self.cfg.tensorboard else None
        if not all_finite(state.learner.params):
            where = ", ".join(f"seed {self.seeds[s]} level {self._plan(s).level} "
                              f"({self._plan(s).name})" for s in self._training())
            raise NonFiniteError(f"non-finite learner parameters in chunk {self.state.chunks} "
                                 f"(training: {where})")
        self.arrays = a.replace(state=state, window=window, task_window=task_window)
        return stats, windows, metrics

    def _tb_level_tag(self, s: int) -> str:
        """Seed ``s``'s TensorBoard prefix for its level (``_plan``: in fine-tuning, the level
        of the option whose turn it is)."""
        plan = self._plan(s)
        return f"seed_{self.seeds[s]}/level_{plan.level}_{plan.name}"

    def _log_learner(self, metrics) -> None:
        """TensorBoard: each training seed's learner metrics of the chunk (the mean over its
        updates: PPO's entropy, approx_kl, losses, ...), at the level's or the phase's env
        steps, under ``seed_S/level_L_NAME/learner/`` or ``seed_S/finetune/NAME/learner/``."""
        if self._tb is None or metrics is None:
            return
        means = {name: np.asarray(value, np.float64) for name, value in metrics.items()}
        for s in self._training():  # (the chunk's seeds: stages change only after this)
            if self._joint_tuning(s):  # (logged by _joint_chunk)
                continue
            if self._finetuning(s):
                tag = f"seed_{self.seeds[s]}/finetune/{self._plan(s).name}"
                counters = self.state.finetune[s]
            else:
                tag, counters = self._tb_level_tag(s), self.state.level[s]
            for name, value in means.items():
                if value.ndim == 2:  # [S, U]: one scalar per update
                    self._tb.add_scalar(f"{tag}/learner/{name}", float(np.mean(value[s])),
                                        counters.env_steps)

    def _evaluate(self, t_start: float) -> dict:
        a, st = self.arrays, self.state
        keys, k_eval = split_seeds(local(a.keys), 2)
        if self.mesh is not None:
            k_eval = dist.place(k_eval, seed_sharding(self.mesh, k_eval))
        # under the run's frozen policy (final_success), then under every other mode
        by_policy = {}
        for policy in [self.engine.frozen_policy] + [
                p for p in EVAL_TEMPERATURES if p != self.engine.frozen_policy]:
            result, compile_s = self.engine.evaluate(
                k_eval, a.bank, a.learned, place=self._place_small, policy=policy)
            st.compile_seconds += compile_s
            by_policy[policy] = dist.gather(result)
        st.wall_seconds = time.perf_counter() - t_start
        if self._tb is not None:
            self._tb.close()
        # a curve row's 7th entry is its slot (a sweep splits the rows by point)
        return {"levels": st.levels, "curves": [r[:6] for r in st.curves],
                "curve_slots": [r[6] if len(r) > 6 else None for r in st.curves],
                "final": by_policy[self.engine.frozen_policy], "final_by_policy": by_policy,
                "eval_policy": self.engine.frozen_policy,
                "finetune": st.finetune_record() if self.ft_order else None,
                "bank": a.bank, "learned": a.learned,
                "wall_seconds": st.wall_seconds, "compile_seconds": st.compile_seconds}

    def _start_levels(self, seeds: list[int]) -> None:
        """Fresh learners, keys and environments for these seeds' next level or fine-tuning
        turn (each seed's keys split exactly as if it trained alone); a turn's learner
        continues from its option's frozen policy."""
        if not seeds:
            return
        # computed for every seed and selected, so that every call has the same shapes
        # (one compile per run, however many seeds start at once)
        a = jax.tree.map(local, self.arrays)
        keys, k_init, k_reset, k_run = split_seeds(a.keys, 4)
        starts = jnp.asarray([self._plan(s).start for s in range(len(self.seeds))], jnp.int32)
        learner = self._init_learner(k_init)
        tuning = [s for s in seeds if self._finetuning(s)]
        if tuning and self.joint:  # a learner per option, from the bank
            fresh = self.engine.joint_state(
                learner.replace(hp={**learner.hp, **self.finetune_hp}), a.bank, k_reset, k_run)
            a = a.replace(joint=select_seeds(self._mask(tuning), fresh, a.joint))
        elif tuning:
            warm = self.engine.warm_start(learner, ft.bank_rows(a.bank, self._options()))
            warm = warm.replace(hp={**warm.hp, **self.finetune_hp})
            learner = select_seeds(self._mask(tuning), warm, learner)
        fresh = SeedState(self.engine.reset(k_reset, starts), learner, k_run)
        # a later fine-tuning turn goes on with the episodes in flight (config docs)
        go_on = [s for s in tuning
                 if self.cfg.finetune_continue_episodes and self.state.finetune[s].turns]
        if go_on:
            carry = select_seeds(self._mask(go_on), self.engine.hand_over(a.state.carry),
                                 fresh.carry)
            fresh = fresh._replace(carry=carry)
        empty = SuccessWindow.empty(len(self.seeds), self.cfg.window_slots)  # a new level's
        keys, state, window = select_seeds(self._mask(seeds), (keys, fresh, empty),
                                           (a.keys, a.state, a.window))
        self.arrays = a.replace(keys=keys, state=state, window=window)
        self._place()
        for s in seeds:
            self.state.start(s)

    def _init_learner(self, keys: jax.Array):
        """Fresh learners per slot, with each slot's swept hyper-parameters."""
        learner = self.engine.init_learner(keys)
        if self.slot_hp:
            learner = learner.replace(hp={**learner.hp, **self.slot_hp})
        return learner

    def _save_due(self) -> bool:
        due = time.perf_counter() - self._last_save >= self.cfg.checkpoint_every
        # clocks differ between processes, and saving is collective: process 0 decides
        return dist.agree(due) if self.cfg.checkpoint_every > 0 else due
