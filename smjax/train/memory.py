"""A run's device memory, estimated before anything compiles.

The estimate counts only what the batch must hold at least: the environment state and
observation of every parallel environment (training, gate and evaluation batches), a
rollout's observations, and a few copies of the live state that XLA keeps while it
updates it. Networks, optimizer state and temporaries come on top, so the estimate is
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


class MemoryEstimateError(ValueError):
    """A batch that cannot fit; the message gives the estimate and the memory available."""


def _bytes(tree) -> int:
    return sum(int(np.prod(x.shape)) * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree))


def per_env_bytes(env, env_params) -> tuple[int, int]:
    """(observation, state) bytes of one environment, from shapes only (nothing runs)."""
    obs, state = jax.eval_shape(env.reset, jax.random.PRNGKey(0), env_params)
    return _bytes(obs), _bytes(state)


def estimate_bytes(obs_bytes: int, state_bytes: int, cfg: TrainConfig, num_seeds: int) -> int:
    live = num_seeds * cfg.num_envs * (obs_bytes + state_bytes) * STATE_COPIES
    rollout = num_seeds * cfg.num_envs * cfg.rollout_ticks * (obs_bytes + TRANSITION_EXTRA_BYTES)
    side = num_seeds * max(cfg.gate_envs, cfg.eval_envs) * (obs_bytes + state_bytes)
    return live + rollout + side


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
    per_tick = num_seeds * cfg.num_envs * cfg.rollout_ticks
    if per_tick > INT32_LIMIT:
        raise MemoryEstimateError(
            f"batch too large: {num_seeds} seeds x num_envs {cfg.num_envs} x rollout_ticks "
            f"{cfg.rollout_ticks} = {per_tick:,} transitions per rollout exceeds 2**31; lower "
            f"--num-envs")
    obs_b, state_b = per_env_bytes(env, env_params)
    need = estimate_bytes(obs_b, state_b, cfg, num_seeds)
    have = available_bytes()
    if have is not None and need > have:
        raise MemoryEstimateError(
            f"batch too large: {num_seeds} seeds x num_envs {cfg.num_envs} (rollout_ticks "
            f"{cfg.rollout_ticks}) needs at least an estimated {_gib(need)}, but "
            f"{jax.devices()[0].platform} memory is {_gib(have)}; lower --num-envs or --seeds")
    return need
