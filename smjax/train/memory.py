"""A run's device memory, estimated before anything compiles.

The estimate counts only what the batch must hold at least: the environment state and
observation of every parallel environment (training, gate and evaluation batches), a
rollout's observations, the pool of episode starts (``reset_pool``), the running-success
windows and what a chunk returns of them per update (``success_window``), and a few
copies of the live state that XLA keeps while it updates it. Networks, optimizer state and temporaries come on top, so the estimate is
a lower bound: a batch it refuses cannot fit, and one it accepts still may not.
"""
from __future__ import annotations

import os

import jax
import numpy as np

from smjax.train.config import TrainConfig

# live copies of the carried state while a step rewrites it (input, output, donation slack)
STATE_COPIES = 3
# per environment and tick of a rollout beyond the observation: action, reward, flags, ...
TRANSITION_EXTRA_BYTES = 32
INT32_LIMIT = 2**31 - 1
# a window's batch slot: float32 total + int32 count, in the learner's and the task's window
WINDOW_SLOT_BYTES = 2 * 8
# a chunk returns, per update and window slot, a float32 total and an int32 count
WINDOW_OUTPUT_BYTES = 8


class MemoryEstimateError(ValueError):
    """A batch that cannot fit; the message gives the estimate and the memory available."""


def _bytes(tree) -> int:
    return sum(int(np.prod(x.shape)) * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree))


def per_env_bytes(env, env_params) -> tuple[int, int]:
    """(observation, state) bytes of one environment, from shapes only (nothing runs or
    compiles: the key is made inside the traced function too)."""
    obs, state = jax.eval_shape(lambda p: env.reset(jax.random.PRNGKey(0), p), env_params)
    return _bytes(obs), _bytes(state)


# what to lower for each part of the estimate
ADVICE = {"batch": "--num-envs or --seeds", "pool": "reset_pool (--set reset_pool=N)",
          "windows": "success_window (--set success_window=N)"}


def estimate_parts(obs_bytes: int, state_bytes: int, cfg: TrainConfig,
                   num_seeds: int) -> dict[str, int]:
    """The estimate's bytes by the setting that sizes them (keys of ``ADVICE``)."""
    env_bytes, run, evaluation = obs_bytes + state_bytes, cfg.run, cfg.evaluation
    live = num_seeds * run.num_envs * env_bytes * STATE_COPIES
    rollout = num_seeds * run.steps_per_update * (obs_bytes + TRANSITION_EXTRA_BYTES)
    side = num_seeds * max(evaluation.gate_envs, evaluation.eval_envs) * env_bytes
    # the pool is carried (copied as the live state) and refilled by a batch of resets
    pool = num_seeds * run.pool_size * env_bytes * (STATE_COPIES + 1)
    return {"batch": live + rollout + side, "pool": pool, "windows": window_bytes(cfg, num_seeds)}


def estimate_bytes(obs_bytes: int, state_bytes: int, cfg: TrainConfig, num_seeds: int) -> int:
    return sum(estimate_parts(obs_bytes, state_bytes, cfg, num_seeds).values())


def window_bytes(cfg: TrainConfig, num_seeds: int) -> int:
    """The running-success windows (carried, so copied as the live state) and the chunk's
    per-update view of them."""
    slots = num_seeds * cfg.window_slots
    return slots * (WINDOW_SLOT_BYTES * STATE_COPIES
                    + cfg.run.updates_per_chunk * WINDOW_OUTPUT_BYTES)


def available_bytes() -> int | None:
    """The first device's memory limit (GPU/TPU), else the host's physical memory."""
    try:
        stats = jax.devices()[0].memory_stats()
    except Exception:  # some backends do not report
        stats = None
    if stats and stats.get("bytes_limit"):
        return int(stats["bytes_limit"])
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def _gib(n: float) -> str:
    return f"{n / 2**30:,.1f} GiB"


def check_fits(env, env_params, cfg: TrainConfig, num_seeds: int) -> int:
    """Refuse a batch whose estimated memory exceeds the device's, or whose element counts
    overflow the int32 indices XLA uses; returns the estimate in bytes."""
    run = cfg.run
    per_tick = num_seeds * run.steps_per_update
    if per_tick > INT32_LIMIT:
        raise MemoryEstimateError(
            f"batch too large: {num_seeds} seeds x num_envs {run.num_envs} x rollout_ticks "
            f"{run.rollout_ticks} = {per_tick:,} transitions per rollout exceeds 2**31; lower "
            f"--num-envs")
    obs_b, state_b = per_env_bytes(env, env_params)
    parts = estimate_parts(obs_b, state_b, cfg, num_seeds)
    need, have = sum(parts.values()), available_bytes()
    if have is not None and need > have:
        largest = max(parts, key=parts.get)
        raise MemoryEstimateError(
            f"batch too large: {num_seeds} seeds x num_envs {run.num_envs} (rollout_ticks "
            f"{run.rollout_ticks}, reset_pool {run.pool_size}, success_window "
            f"{cfg.window_slots}) needs at least an estimated {_gib(need)}, but "
            f"{jax.devices()[0].platform} memory is {_gib(have)}; lower {ADVICE[largest]}")
    return need
