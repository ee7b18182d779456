"""Brax ``Env`` adapter, so Brax's own trainers (PPO, SAC) run on Fetch & Stack.

``BraxFetchEnv(num_blocks=3)`` wraps ``FetchEnv``: ``reset(rng) -> brax State`` and
``step(state, action) -> brax State`` (no auto-reset: wrap it with
``brax.envs.wrappers.training.wrap``, which adds episode limits and auto-reset, exactly as
Brax's trainers expect). ``State.pipeline_state`` is the ``FetchState``; ``info`` carries
``rng``, ``score`` and ``is_success``, ``metrics`` the score and success. ``done`` is 0:
Brax's EpisodeWrapper truncates at ``episode_length`` (pass 50 N for the reference).

Brax 0.14's trainers (``brax.training.agents.ppo.train``, SAC, APG) call
``jax.device_put_replicated``, which JAX 0.10 removed. Importing this module defines it
where it is missing (:func:`device_put_replicated`: JAX's documented drop-in, a stack
over the devices placed with one shard per device), so Brax's PPO trains on this
environment with the versions ``pip install -e ".[peers]"`` installs. Where JAX has its
own, nothing changes.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from brax.envs.base import Env, State
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from smjax.envs.fetch.env import FetchEnv
from smjax.envs.fetch.types import FetchConfig


def device_put_replicated(x, devices):
    """``x``'s leaves stacked once per device, one copy on each: what JAX < 0.10's
    ``jax.device_put_replicated`` returned (the input of a ``pmap`` over ``devices``)."""
    sharding = NamedSharding(Mesh(np.array(devices), ("devices",)), PartitionSpec("devices"))
    return jax.tree.map(
        lambda v: jax.device_put(jnp.stack([jnp.asarray(v)] * len(devices)), sharding), x)


def _install_device_put_replicated() -> None:
    """Brax's trainers need it; JAX 0.10's ``jax`` module answers with an AttributeError."""
    if not hasattr(jax, "device_put_replicated"):
        jax.device_put_replicated = device_put_replicated


_install_device_put_replicated()


class BraxFetchEnv(Env):
    """Fetch & Stack behind Brax's ``Env`` interface."""

    def __init__(self, num_blocks: int = 3, config: FetchConfig | None = None, **kwargs):
        self.fetch = FetchEnv(config or FetchConfig(num_blocks=num_blocks))
        self.params = self.fetch.default_params

    def reset(self, rng: jax.Array) -> State:
        rng, key = jax.random.split(rng)
        obs, fstate = self.fetch.reset_env(key, self.params)
        zero = jnp.zeros((), jnp.float32)
        metrics = {"score": zero, "is_success": zero}
        info = {"rng": rng, "score": zero, "is_success": zero}
        return State(pipeline_state=fstate, obs=obs, reward=zero, done=zero,
                     metrics=metrics, info=info)

    def step(self, state: State, action: jax.Array) -> State:
        rng, key = jax.random.split(state.info["rng"])
        obs, fstate, reward, _, _, info = self.fetch.step_env(
            key, state.pipeline_state, action, self.params)
        score = info["score"].astype(jnp.float32)
        success = info["is_success"].astype(jnp.float32)
        new_info = dict(state.info, rng=rng, score=score, is_success=success)
        metrics = dict(state.metrics, score=score, is_success=success)
        return state.replace(pipeline_state=fstate, obs=obs, reward=reward.astype(jnp.float32),
                             done=jnp.zeros((), jnp.float32), metrics=metrics, info=new_info)

    @property
    def observation_size(self) -> int:
        return self.fetch.config.obs_size

    @property
    def action_size(self) -> int:
        return 4

    @property
    def backend(self) -> str:
        return "mjx"
