"""The host loop shared by top-down, bottom-up and flat training.

It runs compiled chunks (``Engine.chunk``) and, between them, counts episodes, checks
each seed's running success against the threshold, draws progress, records curves and
writes checkpoints; it never steps an environment itself. All seeds train together in
one compiled program; a seed that has finished a level is frozen (its updates are
masked) until every seed has finished it. Everything the loop knows lives in
``arrays`` (device state) and ``host`` (JSON-able counters), which is exactly what a
checkpoint holds, so a resumed run continues bit for bit.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from smjax.options.hierarchy import Hierarchy
from smjax.train import checkpoint as ckpt
from smjax.train import distributed as dist
from smjax.train.config import TrainConfig
from smjax.train.engine import Engine, SeedState
from smjax.train.sharding import seed_sharding, state_shardings, training_mesh


class NonFiniteError(FloatingPointError):
    """A learner produced non-finite parameters (``run`` says which checkpoint is kept)."""


@dataclass
class LevelPlan:
    name: str        # option trained
    option: int      # its option id
    start: int       # option at the bottom of the stack at each reset
    level: int       # the paper's level number


def resolve_hierarchy(env, cfg: TrainConfig) -> tuple[str, Hierarchy]:
    """The hierarchy a run uses: "flat" for the flat method, else the named or default one."""
    options = env.hierarchies()
    if not options:
        raise ValueError(f"environment {env.name!r} declares no hierarchies")
    name = "flat" if cfg.method == "flat" else cfg.hierarchy
    if name is None:
        name = "paper" if "paper" in options else next(iter(options))
    if name not in options:
        raise ValueError(
            f"unknown hierarchy {name!r} for {env.name!r}; valid: {', '.join(options)}")
    return name, options[name]


def plan_levels(h: Hierarchy, method: str) -> list[LevelPlan]:
    """Learning order: top-down (root first), bottom-up (deepest first, each from resets)."""
    names = list(h.learnable)
    if method == "flat":
        names = names[:1]
    if method == "bottom-up":
        names = names[::-1]
    plans = []
    for name in names:
        option = h.option_index(name)
        start = option if (method == "bottom-up" and option != 0) else 0
        plans.append(LevelPlan(name, option, start, h.level(name)))
    return plans


def running_success(history: list, window: int) -> float:
    """Mean success over (at least) the last ``window`` learner episodes (NaN if fewer)."""
    total, count = 0.0, 0
    for s, c in reversed(history):
        total, count = total + s, count + c
        if count >= window:
            break
    return total / count if count >= window else float("nan")


def _gate_counters(num_seeds: int) -> dict:
    """A level's gate bookkeeping per seed (host state, checkpointed)."""
    return {"gate_success": [None] * num_seeds, "gate_attempts": [0] * num_seeds,
            "gate_env_steps": [0] * num_seeds, "gate_next": [0] * num_seeds}


def _split_seeds(keys: jax.Array, n: int) -> list[jax.Array]:
    split = jax.vmap(lambda k: jax.random.split(k, n))(keys)
    return [split[:, i] for i in range(n)]


@jax.jit
def _fold_in(keys: jax.Array, data: jax.Array) -> jax.Array:
    return jax.vmap(jax.random.fold_in, (0, None))(keys, data)


@jax.jit
def _finite_flags(tree) -> jax.Array:
    flags = [jnp.isfinite(x).all() for x in jax.tree.leaves(tree)
             if jnp.issubdtype(x.dtype, jnp.floating)]
    return jnp.stack(flags).all() if flags else jnp.asarray(True)


def _all_finite(tree) -> bool:
    # one compiled reduction, read through ``gather`` so every process sees the same answer
    return bool(dist.gather(_finite_flags(tree)))


def _local(x: jax.Array) -> jax.Array:
    """``x`` as an array this process holds whole (host-side derivations such as key
    splits and learner inits work on it; they are then placed on the mesh again)."""
    return x if x.is_fully_addressable else jnp.asarray(dist.gather(x))


class HierarchyTrainer:
    """Trains every planned level for all seeds; resumable from its checkpoints."""

    def __init__(self, engine: Engine, plans: list[LevelPlan], seeds: list[int], *,
                 out_dir=None, progress: bool = True, run_meta: dict | None = None):
        self.engine, self.plans, self.seeds = engine, plans, list(seeds)
        self.cfg = engine.cfg
        self.cfg.check_level_names([p.name for p in plans])
        self.out_dir = out_dir
        self.writer = dist.is_writer()  # process 0: the only one that writes files or draws bars
        self.progress = progress and self.writer
        self.run_meta = run_meta or {}
        S = len(self.seeds)
        keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(self.seeds, jnp.uint32))
        keys, k_init, k_reset = _split_seeds(keys, 3)
        learner = engine.init_learner(k_init)
        self.arrays = {
            "keys": keys,
            "state": SeedState(engine.reset(k_reset, jnp.asarray(0)), learner, keys),
            "bank": engine.new_bank(learner),
            "learned": jnp.zeros((S, engine.h.num_options), bool),
        }
        self.host: dict[str, Any] = {
            "plan_index": 0, "in_level": False, "levels": [], "curves": [],
            "compile_seconds": 0.0, "wall_seconds": 0.0, "chunks": 0,
        }
        self._compiled = None
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
        arrays = self.arrays
        shardings = {
            "keys": seed_sharding(self.mesh, arrays["keys"]),
            "state": state_shardings(self.mesh, arrays["state"]),
            "bank": seed_sharding(self.mesh, arrays["bank"]),
            "learned": seed_sharding(self.mesh, arrays["learned"]),
        }
        self.arrays = dist.place(arrays, shardings)

    def _place_small(self, tree):
        """Small per-call inputs (flags, masks) on the mesh: with several processes every
        input of a compiled program must be a global array."""
        if self.mesh is None or not dist.is_multiprocess():
            return tree
        return dist.place(tree, seed_sharding(self.mesh, tree))

    # ---- checkpoints -------------------------------------------------------------
    def save(self) -> None:
        """Checkpoint (collective with several processes: all gather, process 0 writes)."""
        if self.out_dir is None:
            return
        meta = {"host": self.host, "run": self.run_meta}
        arrays = dist.gather(self.arrays) if dist.is_multiprocess() else self.arrays
        if self.writer:
            ckpt.save_checkpoint(self.out_dir, self.host["chunks"], arrays, meta)
        self._last_save = time.perf_counter()

    def restore(self) -> bool:
        """Resume from process 0's checkpoint; every process gets the same state."""
        info = ckpt.shared_meta(self.out_dir) if self.out_dir is not None else None
        if info is None:
            return False
        if dist.is_multiprocess():
            like = jax.tree.map(lambda x: np.zeros(x.shape, x.dtype), self.arrays)
            loaded = ckpt.load_arrays(self.out_dir, like) if self.writer else like
            self.arrays = jax.tree.map(jnp.asarray, dist.broadcast(loaded))
        else:
            self.arrays = ckpt.load_arrays(self.out_dir, self.arrays)
        self.host = info["meta"]["host"]
        for k, v in _gate_counters(len(self.seeds)).items():
            self.host.setdefault(k, v)  # checkpoints written before the gate existed
        self._place()
        return True

    # ---- the loop ------------------------------------------------------------------
    def run(self) -> dict:
        t_start = time.perf_counter() - self.host["wall_seconds"]
        while self.host["plan_index"] < len(self.plans):
            plan = self.plans[self.host["plan_index"]]
            if not self.host["in_level"]:
                self._start_level(plan)
            self._train_level(plan, t_start)
            self._finish_level(plan)
            if self.host["plan_index"] < len(self.plans):
                # start the next level before checkpointing: the checkpoint then holds its fresh
                # learner (an empty replay buffer, which compresses to nothing), not the finished
                # one, so a level-boundary checkpoint is small enough to move between machines
                self._start_level(self.plans[self.host["plan_index"]])
            self.host["wall_seconds"] = time.perf_counter() - t_start
            self.save()
        keys, k_eval = _split_seeds(_local(self.arrays["keys"]), 2)
        if self.mesh is not None:
            k_eval = dist.place(k_eval, seed_sharding(self.mesh, k_eval))
        final, compile_s = self.engine.evaluate(k_eval, self.arrays["bank"], self.arrays["learned"],
                                                self.arrays["state"].learner,
                                                place=self._place_small)
        self.host["compile_seconds"] += compile_s
        final = dist.gather(final)
        self.host["wall_seconds"] = time.perf_counter() - t_start
        if self._tb is not None:
            self._tb.close()
        return {"levels": self.host["levels"], "curves": self.host["curves"], "final": final,
                "bank": self.arrays["bank"], "learned": self.arrays["learned"],
                "wall_seconds": self.host["wall_seconds"],
                "compile_seconds": self.host["compile_seconds"]}

    def _start_level(self, plan: LevelPlan) -> None:
        S = len(self.seeds)
        keys, k_init, k_reset, k_run = _split_seeds(_local(self.arrays["keys"]), 4)
        learner = self.engine.init_learner(k_init)
        carry = self.engine.reset(k_reset, jnp.asarray(plan.start))
        self.arrays["keys"] = keys
        self.arrays["state"] = SeedState(carry, learner, k_run)
        self._place()
        self.host.update(in_level=True, episodes=[0] * S, env_steps=[0] * S, reached=[False] * S,
                         active=[True] * S, history=[[] for _ in range(S)], running=[None] * S,
                         **_gate_counters(S))

    def _train_level(self, plan: LevelPlan, t_start: float) -> None:
        cfg, host = self.cfg, self.host
        steps_per_update = cfg.num_envs * cfg.rollout_ticks
        level_cfg = cfg.for_level(plan.name)
        bar = self._bar(plan)
        learner_arr, start_arr = jnp.asarray(plan.option), jnp.asarray(plan.start)
        if self.mesh is not None and dist.is_multiprocess():
            # every input of the compiled chunk must be global when it spans processes
            learner_arr, start_arr = dist.place((learner_arr, start_arr),
                                                seed_sharding(self.mesh, (learner_arr, start_arr)))
        while any(host["active"]):
            active = jnp.asarray(host["active"])
            if self.mesh is not None:
                active = dist.place(active, seed_sharding(self.mesh, active))
            args = (self.arrays["state"], active, self.arrays["bank"], self.arrays["learned"],
                    learner_arr, start_arr)
            if self._compiled is None:  # one compile serves every level (ids are traced)
                t0 = time.perf_counter()
                self._compiled = self.engine.chunk.lower(*args).compile()
                host["compile_seconds"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            state, stats, _ = self._compiled(*args)
            stats = dist.gather(stats)  # [S, U], the same on every process
            dt = time.perf_counter() - t0
            if not _all_finite(state.learner.params):
                raise NonFiniteError(
                    f"non-finite learner parameters at level {plan.level} ({plan.name}) after "
                    f"{max(host['episodes'])} episodes (chunk {host['chunks']})")
            self.arrays["state"] = state
            candidates = self._account(plan, stats, steps_per_update)
            host["chunks"] += 1
            passed = self._accept(plan, candidates)
            for s in range(len(self.seeds)):
                if not host["active"][s]:
                    continue
                if s in passed:
                    host["reached"][s], host["active"][s] = True, False
                elif self._budget_spent(level_cfg, s):
                    host["active"][s] = False
            host["wall_seconds"] = time.perf_counter() - t_start
            if bar is not None:
                self._draw(bar, dt, steps_per_update)
            if self.out_dir is not None and self._save_due():
                self.save()
        if bar is not None:
            bar.close()

    def _save_due(self) -> bool:
        due = time.perf_counter() - self._last_save >= self.cfg.checkpoint_every
        # clocks differ between processes, and saving is collective: process 0 decides
        return dist.agree(due) if self.cfg.checkpoint_every > 0 else due

    def _account(self, plan: LevelPlan, stats, steps_per_update: int) -> list[int]:
        """Count a chunk's episodes and steps; the seeds whose running success reached the
        threshold."""
        cfg, host = self.cfg.for_level(plan.name), self.host
        candidates = []
        for s, seed in enumerate(self.seeds):
            if not host["active"][s]:
                continue
            for u in range(cfg.updates_per_chunk):
                host["episodes"][s] += int(stats.env_episodes[s, u])
                host["env_steps"][s] += steps_per_update
                n = int(stats.learner_episodes[s, u])
                if n:
                    host["history"][s].append([float(stats.learner_success[s, u]), n])
                run = running_success(host["history"][s], cfg.success_window)
                host["running"][s] = None if math.isnan(run) else run
                host["curves"].append([seed, plan.level, plan.name, host["episodes"][s],
                                       host["env_steps"][s], host["running"][s]])
                if self._tb is not None and host["running"][s] is not None:
                    tag = f"seed_{seed}/level_{plan.level}_{plan.name}"
                    self._tb.add_scalar(f"{tag}/running_success", host["running"][s],
                                        host["env_steps"][s])
                    self._tb.add_scalar(f"{tag}/episodes", host["episodes"][s], host["env_steps"][s])
            # keep only as much history as the window needs
            hist, count, keep = host["history"][s], 0, 0
            for _, c in reversed(hist):
                keep, count = keep + 1, count + c
                if count >= cfg.success_window:
                    break
            host["history"][s] = hist[len(hist) - keep:]
            run = host["running"][s]
            if run is not None and run >= cfg.threshold:
                candidates.append(s)
        return candidates

    def _budget_spent(self, cfg: TrainConfig, s: int) -> bool:
        host = self.host
        return host["episodes"][s] >= cfg.max_episodes_per_level or bool(
            cfg.max_steps_per_level and host["env_steps"][s] >= cfg.max_steps_per_level)

    def _accept(self, plan: LevelPlan, candidates: list[int]) -> list[int]:
        """Seeds (of ``candidates``, whose running success reached the threshold) whose
        level ends now: all of them without the gate; with it, those whose frozen policy
        passes a gate attempt (tried every ``gate_interval`` chunks, and once more when
        the budget is spent)."""
        cfg, host = self.cfg.for_level(plan.name), self.host
        if not cfg.gate or not candidates:
            return candidates
        due = [s for s in candidates
               if host["chunks"] >= host["gate_next"][s] or self._budget_spent(cfg, s)]
        if not due:
            return []
        # the attempt number varies the gate's episodes between attempts, deterministically
        keys = _fold_in(self.arrays["keys"], jnp.asarray(host["chunks"], jnp.uint32))
        due_mask = self._place_small(jnp.asarray([s in due for s in range(len(self.seeds))]))
        # one vmapped call for all seeds; those not due are skipped (their results unused)
        result, compile_s = self.engine.gate(
            keys, self.arrays["state"], self.arrays["bank"], self.arrays["learned"],
            plan.option, plan.start, due_mask, cfg.threshold, place=self._place_small)
        host["compile_seconds"] += compile_s
        result = dist.gather(result)
        passed = []
        for s in due:
            success = float(result["success"][s])
            host["gate_success"][s] = success
            host["gate_attempts"][s] += 1
            host["gate_env_steps"][s] += int(result["env_steps"][s])
            host["gate_next"][s] = host["chunks"] + cfg.gate_interval
            if self._tb is not None:
                tag = f"seed_{self.seeds[s]}/level_{plan.level}_{plan.name}"
                self._tb.add_scalar(f"{tag}/gate_success", success, host["env_steps"][s])
            if success >= cfg.threshold:
                passed.append(s)
        return passed

    def _finish_level(self, plan: LevelPlan) -> None:
        host, arrays = self.host, self.arrays
        arrays["bank"] = self.engine.store_in_bank(arrays["bank"], arrays["state"].learner.params,
                                                   plan.option)
        arrays["learned"] = arrays["learned"].at[:, plan.option].set(True)
        self._place()
        host["levels"].append({
            "template": plan.name, "level": plan.level, "episodes": list(host["episodes"]),
            "env_steps": list(host["env_steps"]), "reached": list(host["reached"]),
            "final_running_success": list(host["running"]),
            # the last gate attempt's success (None: never tried), attempts, env steps spent
            "gate_success": list(host["gate_success"]),
            "gate_attempts": list(host["gate_attempts"]),
            "gate_env_steps": list(host["gate_env_steps"]),
        })
        host["plan_index"] += 1
        host["in_level"] = False

    # ---- progress --------------------------------------------------------------------
    def _bar(self, plan: LevelPlan):
        if not self.progress:
            return None
        from tqdm.auto import tqdm

        cfg = self.cfg.for_level(plan.name)
        # a level with an env-step budget counts steps (its episode budget is then usually
        # a formality, e.g. 10**9); otherwise it counts episodes
        self._bar_counts = "env_steps" if cfg.max_steps_per_level else "episodes"
        self._bar_total = cfg.max_steps_per_level or cfg.max_episodes_per_level
        return tqdm(total=self._bar_total, desc=f"level {plan.level} {plan.name}",
                    unit={"env_steps": "step", "episodes": "ep"}[self._bar_counts],
                    unit_scale=True, leave=True,
                    initial=int(np.mean(self.host[self._bar_counts])))

    def _draw(self, bar, dt: float, steps_per_update: int) -> None:
        host = self.host
        bar.n = int(min(np.mean(host[self._bar_counts]), self._bar_total))
        rate = self.cfg.updates_per_chunk * steps_per_update * len(self.seeds) / max(dt, 1e-9)
        runs = [r for r in host["running"] if r is not None]
        gates = [g for g in host["gate_success"] if g is not None]
        extra = {"gate": f"{np.mean(gates):.2f}"} if gates else {}
        extra["done"] = f"{len(self.seeds) - sum(host['active'])}/{len(self.seeds)}"
        if self._bar_counts == "env_steps":  # the bar counts steps: show episodes beside it
            extra["episodes"] = f"{np.mean(host['episodes']):,.0f}"
        bar.set_postfix(success=f"{np.mean(runs) if runs else 0:.2f}", **extra,
                        steps_s=f"{rate:,.0f}")
        bar.refresh()
