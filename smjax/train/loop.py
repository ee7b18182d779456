"""The host loop shared by top-down, bottom-up and flat training.

It runs compiled chunks (``Engine.chunk``) and, between them, counts episodes, checks
each seed's running success against the threshold, draws progress, records curves and
writes checkpoints; it never steps an environment itself. All seeds train together in
one compiled program; a seed that has finished a level is frozen (its updates are
masked) until every seed has finished it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.options.hierarchy import Hierarchy
from smjax.train.config import TrainConfig
from smjax.train.engine import Engine, SeedState


@dataclass
class LevelPlan:
    name: str        # option trained
    option: int      # its option id
    start: int       # option at the bottom of the stack at each reset
    level: int       # the paper's level number


@dataclass
class LevelRecord:
    template: str
    level: int
    episodes: list = field(default_factory=list)
    env_steps: list = field(default_factory=list)
    reached: list = field(default_factory=list)
    final_running_success: list = field(default_factory=list)


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


def _running_success(history: list[tuple[float, int]], window: int) -> float:
    """Mean success over (at least) the last ``window`` learner episodes."""
    total, count = 0.0, 0
    for s, c in reversed(history):
        total, count = total + s, count + c
        if count >= window:
            break
    return total / count if count >= window else float("nan")


def train_hierarchy(engine: Engine, plans: list[LevelPlan], seeds: list[int], *,
                    progress: bool = True, on_chunk: Callable[..., Any] | None = None) -> dict:
    """Train every planned level for all seeds; returns raw results (see ``results.py``)."""
    cfg, h = engine.cfg, engine.h
    S = len(seeds)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds, jnp.uint32))
    bank, learned = None, jnp.zeros((S, h.num_options), bool)
    levels, curves = [], []
    compile_s, t_start = 0.0, time.perf_counter()
    compiled = None
    steps_per_update = cfg.num_envs * cfg.rollout_ticks
    for plan in plans:
        keys, k_init, k_reset, k_run = _split_seeds(keys, 4)
        learner = engine.init_learner(k_init)
        if bank is None:
            bank = engine.new_bank(learner)
        carry = engine.reset(k_reset, jnp.asarray(plan.start))
        state = SeedState(carry, learner, k_run)
        active = np.ones(S, bool)
        record = LevelRecord(plan.name, plan.level)
        episodes = np.zeros(S, np.int64)
        env_steps = np.zeros(S, np.int64)
        reached = np.zeros(S, bool)
        history: list[list[tuple[float, int]]] = [[] for _ in range(S)]
        running = np.full(S, np.nan)
        bar = _progress_bar(progress, plan, cfg.max_episodes_per_level)
        learner_arr, start_arr = jnp.asarray(plan.option), jnp.asarray(plan.start)
        while active.any():
            args = (state, jnp.asarray(active), bank, learned, learner_arr, start_arr)
            if compiled is None:  # one compile serves every level (learner ids are traced)
                t0 = time.perf_counter()
                compiled = engine.chunk.lower(*args).compile()
                compile_s += time.perf_counter() - t0
            t0 = time.perf_counter()
            state, stats, _ = compiled(*args)
            stats = jax.tree.map(np.asarray, stats)  # [S, U]
            dt = time.perf_counter() - t0
            for s in range(S):
                if not active[s]:
                    continue
                for u in range(cfg.updates_per_chunk):
                    episodes[s] += int(stats.env_episodes[s, u])
                    env_steps[s] += steps_per_update
                    n = int(stats.learner_episodes[s, u])
                    if n:
                        history[s].append((float(stats.learner_success[s, u]), n))
                    running[s] = _running_success(history[s], cfg.success_window)
                    curves.append((seeds[s], plan.level, plan.name, int(episodes[s]),
                                   int(env_steps[s]), running[s]))
                if running[s] >= cfg.threshold:
                    reached[s], active[s] = True, False
                elif episodes[s] >= cfg.max_episodes_per_level:
                    active[s] = False
            if bar is not None:
                bar.n = int(min(episodes.mean(), cfg.max_episodes_per_level))
                rate = cfg.updates_per_chunk * steps_per_update * S / max(dt, 1e-9)
                bar.set_postfix(success=f"{np.nanmean(running) if np.isfinite(running).any() else 0:.2f}",
                                done=f"{int((~active).sum())}/{S}", steps_s=f"{rate:,.0f}")
                bar.refresh()
            if on_chunk is not None:
                on_chunk(plan=plan, state=state, episodes=episodes, running=running)
        if bar is not None:
            bar.close()
        bank = engine.store_in_bank(bank, state.learner.params, plan.option)
        learned = learned.at[:, plan.option].set(True)
        record.episodes, record.env_steps = episodes.tolist(), env_steps.tolist()
        record.reached = reached.tolist()
        record.final_running_success = [None if np.isnan(x) else float(x) for x in running]
        levels.append(record)
    keys, k_eval = _split_seeds(keys, 2)
    t0 = time.perf_counter()
    evaluate = engine.evaluate.lower(k_eval, bank, learned).compile()
    compile_s += time.perf_counter() - t0
    final = jax.tree.map(np.asarray, evaluate(k_eval, bank, learned))
    wall = time.perf_counter() - t_start
    return {"levels": levels, "curves": curves, "final": final, "bank": bank,
            "learned": learned, "wall_seconds": wall, "compile_seconds": compile_s}


def _split_seeds(keys: jax.Array, n: int) -> list[jax.Array]:
    split = jax.vmap(lambda k: jax.random.split(k, n))(keys)
    return [split[:, i] for i in range(n)]


def _progress_bar(enabled: bool, plan: LevelPlan, total: int):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=f"level {plan.level} {plan.name}", unit="ep", leave=True)
