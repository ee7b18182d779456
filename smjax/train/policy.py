"""Load a trained hierarchy from a run directory and play it (for ``smjax render``)."""
from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.registry import make
from smjax.options.runner import NO_OPTION, Controls
from smjax.train import checkpoint as ckpt
from smjax.train.config import resolve_config
from smjax.train.engine import Engine, make_learner
from smjax.train.loop import CHECKPOINT_FORMAT, HierarchyTrainer
from smjax.train.plans import declared_identity, plan_levels, resolve_hierarchy, stage_count
from smjax.train.restorable import check_restorable


def load_trained(run_dir: str | Path, *, partial: bool = False, task: str | None = None,
                 hierarchy=None, seed_index: int | None = None):
    """(engine, bank, learned, seeds) of the run checkpointed in ``run_dir``.

    A run stopped before its last level would play a partly untrained hierarchy: refused
    unless ``partial``. ``task``, when given, must be the run's task. A run trained with a
    declared hierarchy (``run(..., hierarchy=Hierarchy)``) needs the same one here.
    ``seed_index``, when given, must name one of the run's seeds. Every refusal comes
    before the engine compiles anything."""
    info = ckpt.load_meta(run_dir)
    if info is None:
        raise FileNotFoundError(f"{run_dir} holds no checkpoint (train with --out {run_dir} first)")
    run = info["meta"]["run"]
    if task is not None and run["task"] != task:
        raise ValueError(f"{run_dir} is a run of {run['task']!r}, not {task!r}")
    # (checkpoints of older versions record tensorboard in the run: playing writes no events)
    cfg = resolve_config(saved_run=run, sets={"tensorboard": False})
    declared = run.get("hierarchy_declared")
    if declared is not None and hierarchy is None:
        raise ValueError(f"{run_dir} was trained with a hierarchy declared in code "
                         f"({declared['task']!r}); pass the same Hierarchy (hierarchy=...) to "
                         f"load or play it")
    if hierarchy is not None and (declared is None or declared_identity(hierarchy) != declared):
        raise ValueError(f"{run_dir} was not trained with this hierarchy")
    env, params = make(run["task"], **run["env_overrides"])
    _, hierarchy = resolve_hierarchy(env, cfg, hierarchy)
    plans = plan_levels(hierarchy, cfg.method)
    seeds = run["seeds"]
    checked = check_restorable(run_dir, None, len(seeds), stage_count(hierarchy, plans, cfg),
                               CHECKPOINT_FORMAT)
    done, total = min(checked[0]["meta"]["host"]["stage"]), len(plans)
    if done < total and not partial:
        raise ValueError(f"{run_dir} stopped with a seed after {done} of {total} levels, so its hierarchy is "
                         f"partly untrained; finish it with `smjax train {run['task']} --resume "
                         f"{run_dir}`, or pass --partial to play it anyway")
    if seed_index is not None and not 0 <= seed_index < len(seeds):
        raise ValueError(f"seed_index (--seed-index) must be in [0, {len(seeds)}), got {seed_index}")
    engine = Engine(env, params, hierarchy, make_learner(env, params, cfg), cfg)
    trainer = HierarchyTrainer(engine, plans, seeds, out_dir=run_dir, progress=False,
                               run_meta=run)
    trainer.restore(checked=checked)
    return engine, trainer.arrays.bank, trainer.arrays.learned, seeds


def play_trained(run_dir: str | Path, *, seed_index: int = 0, max_ticks: int = 500, key=None,
                 partial: bool = False, task: str | None = None, hierarchy=None):
    """States of one episode of the trained hierarchy (no teleports), seed ``seed_index``."""
    engine, bank, learned, seeds = load_trained(run_dir, partial=partial, task=task,
                                                hierarchy=hierarchy, seed_index=seed_index)
    bank = jax.tree.map(lambda x: x[seed_index], bank)
    learned = learned[seed_index]
    runner = engine.runner
    controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0), learned, jnp.asarray(False),
                        acts_frozen=True)  # nobody learns: no learner state to explore with
    key = jax.random.PRNGKey(0) if key is None else key
    key, k_reset, _ = jax.random.split(key, 3)  # (the third key once made a dummy learner)
    carry = runner.reset(k_reset, controls, 1)
    tick = jax.jit(lambda c, k: runner.tick(c, k, None, bank, controls))  # nobody learns
    states, total = [jax.tree.map(lambda x: x[0], carry.env_state)], 0.0
    for _ in range(max_ticks):
        key, k = jax.random.split(key)
        new, tr, ends = tick(carry, k)
        total += float(tr.reward[0])
        if bool(ends.reset[0]):
            break  # the next state already belongs to a new episode
        carry = new
        states.append(jax.tree.map(lambda x: x[0], carry.env_state))
    return engine.env, engine.env_params, states, total


def play_random(task: str, *, steps: int = 100, seed: int = 0, env_overrides: dict | None = None):
    """States of a uniformly random policy (one environment, auto-reset)."""
    env, params = make(task, **(env_overrides or {}))
    key = jax.random.PRNGKey(seed)
    key, k = jax.random.split(key)
    _, state = env.reset(k, params)
    step = jax.jit(env.step)
    space = env.action_space(params)
    states = [state]
    for _ in range(steps):
        key, k_act, k_step = jax.random.split(key, 3)
        _, state, *_ = step(k_step, state, space.sample(k_act), params)
        states.append(state)
    return env, params, states


def frames_of(env, params, states) -> list[np.ndarray]:
    return [np.asarray(env.render(s, params), np.uint8) for s in states]
