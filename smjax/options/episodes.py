"""Whole episodes of a hierarchy run by its frozen policies: the program behind a level's
gate, the final evaluation and a saved policy's evaluation, so the three measure alike.

``first_episodes`` runs a batch of environments until each has finished one episode of
the option being examined; ``early_stop_bounds`` lets it stop once a threshold's verdict
is certain; ``eval_temperatures`` names how the frozen policies pick.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.env import over_seeds
from smjax.options.bank import option_temperatures
from smjax.options.carry import Controls

# the frozen-policy modes final_success is measured under (temperature; 0 = argmax; a
# pair: the root's, then every template's): results.json reports every one
# (final_success_by_policy)
EVAL_TEMPERATURES = {"greedy": 0.0, "sample": 1.0, "sample_t0.5": 0.5,
                     "options_t0.5": (1.0, 0.5)}


def eval_temperatures(policy: str, num_options: int, option_temperature: float = 1.0) -> jax.Array:
    """float32 [O]: each option's temperature under an evaluation mode (0 is the root);
    "sample" samples the templates at ``option_temperature`` (TrainConfig's)."""
    if policy not in EVAL_TEMPERATURES:
        raise ValueError(f"policy must be one of {tuple(EVAL_TEMPERATURES)}, got {policy!r}")
    t = EVAL_TEMPERATURES[policy]
    root, templates = t if isinstance(t, tuple) else (t, t)
    if policy == "sample":
        templates = option_temperature
    return jnp.asarray(option_temperatures(root, templates, num_options))


def early_stop_bounds(thresholds: list) -> tuple:
    """Per seed, ``first_episodes``' ``decide`` input for a verdict at that threshold
    (None: run every episode to its end). The float32 bounds are rounded outwards, so a
    stop agrees with a caller's float64 comparison."""
    on, up, down = [], [], []
    for threshold in thresholds:
        if threshold is None:
            on.append(False), up.append(np.inf), down.append(-np.inf)
            continue
        t = np.float32(threshold)
        on.append(True)
        up.append(t if float(t) >= threshold else np.nextafter(t, np.float32(np.inf)))
        down.append(t if float(t) <= threshold else np.nextafter(t, np.float32(-np.inf)))
    return (jnp.asarray(on, bool), jnp.asarray(up, jnp.float32), jnp.asarray(down, jnp.float32))


class FrozenLearner(NamedTuple):
    """What the runner reads of a learner that acts as it will once frozen: its params
    alone, so an evaluation can pass any tree of their shape."""

    params: Any


def first_episodes(runner, key, learner_params, bank, learned, learner, start, teleport,
                   temperature, max_ticks, skip, decide, num_envs: int, *,
                   gamma: float) -> dict:
    """Run ``num_envs`` environments of ``runner`` (a ``HierarchyRunner``) until each has
    finished one learner episode (or ``max_ticks``); each environment's first episode
    counts, so short episodes are not over-represented, and one still unfinished at
    ``max_ticks`` counts as a failure. An environment whose levels above never called the
    learner by ``max_ticks`` says nothing about it and is left out of the means
    (``uncalled``: their share): counted as failures they would hold a deep level's gate
    below its threshold however well the option did where it was called.
    ``skip``: start as finished (under ``vmap`` a skipped seed does not keep the loop
    running for the others; its result is meaningless).

    ``decide = (on, pass_at, fail_below)``: a gate only needs to know whether the mean
    success reaches its threshold. With successes in [0, 1], once the finished episodes
    alone reach ``pass_at``, or even all unfinished ones succeeding could not reach
    ``fail_below``, the answer is certain and the episodes stop (``on``): the same
    decision, fewer ticks. The success then reported is the mean so far (unfinished
    episodes count 0), which lies on the same side of the threshold.
    ``temperature``: float [O], how each frozen policy (and the learner) picks, 0 = greedy.
    ``gamma``: the run's discount (the ticks' ``Controls`` hold one; no record is kept
    here, so it changes no result)."""
    controls = Controls(learner, start, learned, gamma=gamma, teleport=teleport,
                        continue_episodes=jnp.asarray(False), temperature=temperature,
                        acts_frozen=True)
    k_reset, key = jax.random.split(key)
    carry = runner.reset(k_reset, controls, num_envs)
    on, pass_at, fail_below = decide

    def certain(done, success):
        total = jnp.where(done, success, 0.0).sum() / num_envs
        best = total + (~done).sum() / num_envs
        return on & ((total >= pass_at) | (best < fail_below))

    def cond(c):
        _, _, done, _, success, t = c
        return ~done.all() & (t < max_ticks) & ~certain(done, success)

    def body(c):
        carry, key, done, ret, success, t = c
        key, k = jax.random.split(key)
        carry, _, ends = runner.tick(carry, k, FrozenLearner(learner_params), bank, controls)
        first = ends.finished & ~done
        ret = jnp.where(first, ends.ret, ret)
        success = jnp.where(first, ends.success, success)
        return carry, key, done | ends.finished, ret, success, t + 1

    zeros = jnp.zeros((num_envs,), jnp.float32)
    init = (carry, key, jnp.full((num_envs,), skip, bool), zeros, zeros, jnp.asarray(0))
    carry, _, done, ret, success, ticks = jax.lax.while_loop(cond, body, init)
    # (unfinished and not started now: no learner episode ever started there. The early
    # stops above stay exact: leaving such environments out can only move the mean
    # between the two bounds ``certain`` uses)
    uncalled = ~done & ~carry.learner_started
    counted = jnp.maximum(num_envs - uncalled.sum(), 1)
    return {"return": ret.sum() / counted, "success": success.sum() / counted,
            "completed": done.mean(), "uncalled": uncalled.mean(),
            "env_steps": ticks * num_envs}


# ``first_episodes``' axes under a vmap over seeds: teleport and max_ticks are shared,
# ``num_envs`` is static
SEED_AXES = (0, 0, 0, 0, 0, 0, None, 0, None, 0, 0)
SKIP = 9  # the position of ``skip`` among them


def seed_batched_episodes(runner, gamma: float, seed_by_seed: bool = False):
    """``first_episodes`` of ``runner`` (at discount ``gamma``) compiled over a leading
    seed axis: ``f(key, learner_params, bank, learned, learner, start, teleport,
    temperature, max_ticks, skip, decide, num_envs)``.

    Side by side (``vmap``), every seed ticks until the last one's episodes end and a
    skipped seed costs as much as the others: right where seeds run in parallel (a GPU).
    ``seed_by_seed`` runs them one after another (``lax.map``), each until its own episodes
    end, and a skipped seed not at all: right where compute is serial (a CPU), as in a gate
    or a fine-tuning check that concerns one seed of many. Each seed's result is the same."""
    def episodes(*args):
        def run():
            return first_episodes(runner, *args, gamma=gamma)

        if not seed_by_seed:
            return run()

        def skipped():  # nothing due: zeros (a skipped seed's result is meaningless)
            return jax.tree.map(lambda r: jnp.zeros(r.shape, r.dtype), jax.eval_shape(run))

        return jax.lax.cond(args[SKIP], skipped, run)

    return jax.jit(over_seeds(episodes, seed_by_seed, SEED_AXES + (None,)),
                   static_argnums=(11,))
