"""The driver loop shared by top-down, bottom-up and flat training.

All seeds train together in one compiled program, each at its own stage (a level, or
fine-tuning: :mod:`smjax.train.stages`): a seed that finishes a level starts the next one
in the next chunk instead of waiting for the slowest seed, and a seed's numbers do not
depend on the other seeds. The loop is::

    while a seed is training:
        chunk    (ChunkRunner: the compiled programs, each seed run as its stage's controls say)
        account  (each stage counts the chunk toward its seeds' counters)
        decide   (each stage's gates and budgets: which seeds end a level, turn or phase)
        finish, start   (the ended seeds' learners frozen; their next stage set up)
        hooks    (progress bar, TensorBoard, checkpoints: smjax.train.hooks)

It never steps an environment itself. Everything it knows lives in ``arrays`` (device
state, ``TrainArrays``) and ``state`` (host counters, ``TrainerState``; both in
:mod:`smjax.train.state`): exactly what a checkpoint holds, so a resumed run continues bit
for bit.
"""
from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.timeline import TIMELINE
from smjax.train import distributed as dist
from smjax.train.ahead import CompileAhead, arguments, placed
from smjax.train.chunks import ChunkRunner
from smjax.options.episodes import EVAL_TEMPERATURES
from smjax.train.engine import Engine, SeedState
from smjax.train.finetune import FinetuneStage
from smjax.train.finetune_ops import check_finetune_agent, finetune_hp
from smjax.train.hooks import CheckpointHook, ChunkReport, Hook, TensorBoardHook, import_ahead
from smjax.train.levels import LevelStage, freeze_learners
from smjax.train.plans import LevelPlan
from smjax.train.progress import ProgressBar
from smjax.train.seed_arrays import (  # noqa: F401 - NonFiniteError re-exported
    NonFiniteError, final_evaluation_keys, select_seeds, split_seeds,
)
from smjax.train.seed_threads import group_count
from smjax.train.sharding import seed_sharding, training_mesh
from smjax.train.slots import Slots
from smjax.train.stages import ChunkOut, Ends, Scalar, SeedControls, Stage
from smjax.train.state import SuccessWindow, TrainArrays, TrainerState


def default_hooks(cfg, out_dir, progress: bool, run_meta: dict) -> list[Hook]:
    """The progress bar (process 0, unless ``progress`` is off), TensorBoard (process 0,
    where ``cfg.run.tensorboard`` and an output directory) and checkpoints (``out_dir``)."""
    writer = dist.is_writer()  # process 0: the only one that writes files or draws bars
    hooks: list[Hook] = [ProgressBar()] if progress and writer else []
    if cfg.run.tensorboard and out_dir is not None and writer:
        hooks.append(TensorBoardHook(Path(out_dir) / "tensorboard"))
    if out_dir is not None:
        hooks.append(CheckpointHook(out_dir, cfg, run_meta or {}))
    return hooks


class HierarchyTrainer:
    """Trains every planned level for all seeds, each seed at its own pace; resumable."""

    def __init__(self, engine: Engine, plans: list[LevelPlan], seeds: list[int], *,
                 out_dir=None, progress: bool = True, run_meta: dict | None = None,
                 hp: dict | None = None, configs: list | None = None,
                 hooks: list[Hook] | None = None, ahead: CompileAhead | None = None):
        """``seeds``: one per slot (a sweep repeats them, once per point); ``hp``: per slot,
        the learner's sweepable hyper-parameters that differ from its config; ``configs``:
        per slot, the config its run alone has (a sweep point's; default the engine's).
        ``hooks``: the side jobs (default: ``default_hooks``). ``ahead``: where the run's
        programs compile ahead (``smjax.train.ahead``; with ``from_start``, the level chunk
        from here on, while the trainer builds its state; None: the backend's, its level
        chunk compiled where it first runs)."""
        cfg = self.cfg = engine.cfg
        self.engine, self.plans, self.seeds = engine, plans, list(seeds)
        S = len(self.seeds)
        self.slots = Slots(self.seeds, configs if configs is not None else [cfg] * S,
                           {k: jnp.asarray(v, jnp.float32) for k, v in (hp or {}).items()},
                           training_mesh(S, cfg.run.num_envs))
        self.levels = LevelStage(engine, cfg, plans, self.slots)
        # after the levels, a seed fine-tunes (one stage more) unless it is off
        self.finetune = FinetuneStage(engine, cfg, plans, self.slots) if cfg.fine_tuning.on else None
        self.stages: list[Stage] = [self.levels] + ([self.finetune] if self.finetune else [])
        self.num_stages = len(plans) + (self.finetune is not None)
        self.state = TrainerState.new(plans, S)
        self.hooks = (default_hooks(cfg, out_dir, progress, run_meta) if hooks is None
                      else list(hooks))
        for hook in self.hooks:  # the seeds and stages are known; the programs are not
            hook.prepare(self)
        self.runner = ChunkRunner(engine, self.slots, metrics=cfg.run.tensorboard)
        self.ahead = ahead if ahead is not None else CompileAhead.for_backend()
        self.ahead_rest = False  # the rest submitted: gate, joint chunk, evaluation
        # the results calls the hooks get after ``end``: ``smjax.train.run`` sets it (one a
        # run, one a sweep point); none where the trainer is run on its own
        self.results_due = 0
        try:
            self._build_state(ahead)
        except BaseException:
            self.close_hooks()
            raise

    def _build_state(self, ahead: CompileAhead | None) -> None:
        """The slots' first device state (the large programs submitted to ``ahead`` first,
        where it compiles from the start)."""
        cfg = self.cfg
        keys = self.slots.committed(
            jax.vmap(jax.random.PRNGKey)(jnp.asarray(self.seeds, jnp.uint32)))
        if ahead is not None and ahead.on and ahead.from_start and self.slots.mesh is None:
            # the programs compile from the state's shapes (traced: nothing runs), after a
            # bad fine-tuning setting is refused
            shapes = jax.eval_shape(self.initial_arrays, keys)
            check_finetune_agent(cfg, shapes.state.learner.hp)
            shapes = placed(shapes, keys.sharding)
            controls = self.controls()
            self.runner.level_ahead(ahead, controls, shapes)
            self.compile_ahead(controls, shapes)
        self.slots.set(self.initial_arrays(keys))
        # refused even where fine-tuning is off
        tuning_hp = finetune_hp(cfg, self.arrays.state.learner.hp)
        if self.finetune is not None:
            self.finetune.hp = tuning_hp

    def initial_arrays(self, keys: jax.Array) -> TrainArrays:
        """Every slot's device state before its first stage starts, from its key [S]: a
        function of the keys alone, so its shapes are known before it runs."""
        engine, S = self.engine, len(self.seeds)
        keys, k_init, k_reset = split_seeds(keys, 3)
        learner = self.slots.init_learner(engine, k_init)
        joint = self.finetune is not None and self.finetune.joint
        bank = engine.new_bank(learner)
        # host zeros: the trainer commits them to the device (no program per array)
        return TrainArrays(
            bank=bank, keys=keys, learned=np.zeros((S, engine.h.num_options), bool),
            state=SeedState(engine.reset(k_reset, np.zeros((S,), np.int32)), learner, keys),
            **SuccessWindow.pair(S, self.cfg.window_slots, np),
            levels_bank=bank if self.finetune else None,  # arrays are immutable: no copy
            joint=(engine.joint_state(learner, bank, k_reset, keys) if joint else None))

    @property
    def arrays(self) -> TrainArrays:
        return self.slots.arrays

    def restore(self, step: str | None = None, checked: dict | None = None) -> bool:
        """Resume from the checkpoint hook's checkpoint (its latest, or ``step``); False
        where there is none. ``checked``: what ``check_restorable`` returned for it, where
        the caller checked it before building this trainer (its files are hashed once)."""
        saver = next((h for h in self.hooks if isinstance(h, CheckpointHook)), None)
        loaded = saver and saver.load(self.arrays, self.num_stages, step, checked)
        if not loaded:
            return False
        arrays, self.state = loaded
        self.slots.set(arrays)
        return True

    # ---- the loop ------------------------------------------------------------------
    def run(self) -> dict:
        """Train every seed through its stages; evaluate; the run's raw results."""
        st = self.state
        t_start = time.perf_counter() - st.wall_seconds
        try:
            self.timed("start levels (learner init, env reset)", self.start,
                       [s for s in self.training() if not st.started[s]])
            for hook in self.hooks:
                hook.start(self)
            import_ahead(self.hooks)
            return self.train_and_evaluate(t_start)
        finally:
            self.ahead.close()
            self.close_hooks()

    def close_hooks(self) -> None:
        """Every hook's ``close``: the trainer stops, done or not."""
        for hook in self.hooks:
            hook.close()

    def train_and_evaluate(self, t_start: float) -> dict:
        """The driver loop: chunks, the stages' accounts and decisions, hooks; then the
        evaluation."""
        st = self.state
        while self.training():
            t0 = time.perf_counter()
            training, controls = self.training(), self.controls()
            out = self.timed("training chunks", self.chunk, training, controls)
            seconds = time.perf_counter() - t0
            st.chunks += 1
            scalars = []
            for stage in reversed(self.stages):  # fine-tuning's curve rows first
                scalars += stage.account(st, self.held(stage, training), out)
            ends = Ends()
            scalars += self.timed("gates", self.decide, training, controls, ends)
            st.wall_seconds = time.perf_counter() - t_start
            if ends:
                self.timed("level and turn changes", self.change, ends, controls)
            self.report(seconds, scalars, bool(ends))
        for hook in self.hooks:
            hook.end(self)
        return self.timed("evaluation", self.evaluate, t_start)

    def change(self, ends: Ends, controls: list[SeedControls]) -> None:
        """The ended seeds' stages finished, their next ones started."""
        st = self.state
        for stage in self.stages:
            stage.finish(st, ends, [c.option for c in controls])
        # started before the hooks run, so a checkpoint holds the fresh learners
        # (an empty replay buffer compresses to nothing), not the finished ones
        self.start([s for s in ends.levels + ends.turns if st.stage[s] < self.num_stages])

    def training(self) -> list[int]:
        """Seeds that still have a stage to train."""
        return [s for s, i in enumerate(self.state.stage) if i < self.num_stages]

    def stage_of(self, s: int) -> Stage | None:
        """The stage seed ``s`` is in (None: done)."""
        return next((x for x in self.stages if x.holds(self.state, s)), None)

    def held(self, stage: Stage, seeds: list[int]) -> list[int]:
        return [s for s in seeds if stage.holds(self.state, s)]

    def finetuning(self, s: int) -> bool:
        return self.finetune is not None and self.finetune.holds(self.state, s)

    def controls(self) -> list[SeedControls]:
        """Per seed, what its next chunk does (a done seed's row is inactive: it keeps its
        last level's values)."""
        return [(self.stage_of(s) or self.levels).controls(self.state, s)
                for s in range(len(self.seeds))]

    def chunk(self, training: list[int], controls: list[SeedControls]) -> ChunkOut:
        """The compiled chunk for every training seed, as its controls say."""
        st, tuning = self.state, self.finetune
        joint = tuning.joint_controls() if tuning is not None and tuning.joint else None
        where = lambda: ", ".join(  # noqa: E731
            f"seed {self.seeds[s]} level {c.level} ({c.name})"
            for s, c in ((s, self.stage_of(s).plan(st, s)) for s in training))
        # where the level chunk compiles here, the rest compile beside it or after it, as
        # the ahead says (``CompileAhead.beside_main``; ``rehearse_changes`` says why)
        beside = self.ahead.beside_main
        if beside:
            self.compile_ahead(controls)
        out, compile_s = self.runner.run(
            controls, [s in training for s in range(len(self.seeds))], joint, st.chunks, where)
        st.compile_seconds += compile_s
        if not beside:
            self.compile_ahead(controls)
        return out

    def compile_ahead(self, controls: list[SeedControls], shapes: TrainArrays | None = None
                      ) -> None:
        """The gate's, joint fine-tuning's and the evaluation's programs, compiled on the
        ahead's threads while the chunks run (``smjax.train.ahead`` says when), once;
        ``shapes``: the state's, where it is not built yet."""
        if self.ahead_rest:
            return
        st, ahead, self.ahead_rest = self.state, self.ahead, True
        if ahead.on and shapes is None and not ahead.beside_main:
            self.rehearse_changes()
        a = self.arrays if shapes is None else shapes
        if any(self.levels.holds(st, s) for s in self.training()):
            self.levels.gate_ahead(st, controls, ahead, a)
        if self.finetune is not None and self.finetune.joint:
            self.runner.joint_ahead(ahead, *self.finetune.joint_controls(), a)
        evaluation = lambda a: self.engine.evaluate_args(  # noqa: E731
            a.keys, a.bank, a.learned, place=self.slots.small)
        self.engine.episodes_ahead(arguments(evaluation, a), self.cfg.evaluation.eval_envs,
                                   ahead)

    def rehearse_changes(self) -> None:
        """A level change and a stage start that change no seed (every mask off), so that
        their small programs compile now: on a CPU a program compiled while a compile ahead
        runs waits for it (seconds, for what takes a tenth of one alone)."""
        freeze_learners(self.slots, [], [c.option for c in self.controls()])
        self.start([], rehearse=True)

    def decide(self, training: list[int], controls: list[SeedControls], ends: Ends) -> list:
        """Every stage's decisions on the chunk, into ``ends``; the gates' scalars."""
        return [x for stage in self.stages
                for x in stage.decide(self.state, self.held(stage, training), controls, ends)]

    def start(self, seeds: list[int], rehearse: bool = False) -> None:
        """Fresh learners, keys and environments for these seeds' next level or fine-tuning
        turn (each seed's keys split exactly as if it trained alone). ``rehearse``: with no
        seeds, run every step anyway (fine-tuning's start included), changing nothing."""
        if not seeds and not rehearse:
            return
        slots = self.slots
        # computed for every seed and selected, so that every call has the same shapes
        # (one compile per run, however many seeds start at once)
        a = slots.local()
        keys, k_init, k_reset, k_run = split_seeds(a.keys, 4)
        controls = self.controls()
        starts = np.asarray([c.start for c in controls], np.int32)
        fresh = SeedState(self.engine.reset(k_reset, starts),
                          slots.init_learner(self.engine, k_init), k_run)
        tuning = self.held(self.finetune, seeds) if self.finetune is not None else []
        if tuning or (rehearse and self.finetune is not None):
            fresh, a = self.finetune.start(self.state, tuning, fresh, a, k_reset,
                                           [c.option for c in controls])
        empty = SuccessWindow.empty(len(slots), self.cfg.window_slots, np)  # a new level's
        keys, state, window = select_seeds(slots.mask(seeds), (keys, fresh, empty),
                                           (a.keys, a.state, a.window))
        slots.set(a.replace(keys=keys, state=state, window=window))
        for s in seeds:
            self.state.start(s)

    def report(self, seconds: float, scalars: list[Scalar], stage_ended: bool) -> None:
        """Hand the chunk's report to every hook."""
        st, cfg, training = self.state, self.cfg, self.training()
        report = ChunkReport(
            chunk=st.chunks, seconds=seconds,
            steps=cfg.run.steps_per_chunk * len(training),
            scalars=scalars, seeds=[self.stage_of(s).status(st, s) for s in training],
            stages_done=int(sum(st.stage)), stage_ended=stage_ended)
        for hook in self.hooks:
            hook.chunk(self, report)

    def timed(self, label: str, fn, *args):
        """``fn(*args)``, its seconds on the timeline under ``label`` and the compiling
        inside it under ``compile: label`` (apart, so the two never overlap)."""
        compiled, began = self.state.compile_seconds, TIMELINE.now()
        out = fn(*args)
        compiling = self.state.compile_seconds - compiled
        TIMELINE.add(label, began, TIMELINE.now() - began - compiling)
        if compiling:
            TIMELINE.add(f"compile: {label}", began, compiling)
        return out

    def evaluate(self, t_start: float) -> dict:
        """The trained hierarchies on fresh teleport-free episodes, under the run's frozen
        policy (final_success) and, where ``eval_policies`` says "all", every other mode;
        the run's raw results."""
        a, st = self.arrays, self.state
        # a saved policy keeps these keys (``eval_keys``), so evaluating it reproduces this
        eval_keys = k_eval = final_evaluation_keys(a.keys)
        if self.slots.mesh is not None:
            k_eval = dist.place(k_eval, seed_sharding(self.slots.mesh, k_eval))
        by_policy, policies = {}, [self.engine.frozen_policy]
        if self.cfg.evaluation.eval_policies == "all":
            policies += [p for p in EVAL_TEMPERATURES if p not in policies]
        for policy in policies:
            result, compile_s = self.engine.evaluate(
                k_eval, a.bank, a.learned, place=self.slots.small, policy=policy)
            st.compile_seconds += compile_s
            by_policy[policy] = dist.gather(result)
        st.wall_seconds = time.perf_counter() - t_start
        # a curve row's 7th entry is its slot (a sweep splits the rows by point)
        return {"levels": st.levels, "curves": [r[:6] for r in st.curves],
                "curve_slots": [r[6] if len(r) > 6 else None for r in st.curves],
                "final": by_policy[self.engine.frozen_policy], "final_by_policy": by_policy,
                "eval_policy": self.engine.frozen_policy,
                "finetune": st.finetune_record() if self.finetune else None,
                "bank": a.bank, "learned": a.learned, "eval_keys": eval_keys,
                "wall_seconds": st.wall_seconds, "compile_seconds": st.compile_seconds,
                "seed_threads": group_count(self.engine.seed_threads, len(self.slots))}
