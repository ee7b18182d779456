"""Wrappers: episode statistics and the legacy five-value gymnax step."""
from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from smjax.core.adapters import gymnax_params, to_gymnax_space, unwrap_params
from smjax.core.env import Environment


class EnvWrapper:
    """Forwards everything to the wrapped environment unless overridden."""

    def __init__(self, env: Environment):
        self._env = env

    def __getattr__(self, name: str) -> Any:
        # copy/pickle build the object without __init__ and probe it before _env exists:
        # looking _env up through __getattr__ again would recurse forever
        if name == "_env" or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self._env, name)


@struct.dataclass
class EpisodeStatsState:
    env_state: Any
    episode_return: jax.Array
    episode_length: jax.Array
    returned_episode_return: jax.Array
    returned_episode_length: jax.Array
    episodes_done: jax.Array


class EpisodeStatistics(EnvWrapper):
    """Tracks per-episode return and length.

    ``info`` gains ``episode_return``/``episode_length`` (of the last finished episode),
    ``returned_episode`` (True on the step an episode ended) and ``episodes_done``.
    """

    def reset(self, key, params=None):
        obs, env_state = self._env.reset(key, params)
        zero_f = jnp.zeros((), jnp.float32)
        zero_i = jnp.zeros((), jnp.int32)
        return obs, EpisodeStatsState(env_state, zero_f, zero_i, zero_f, zero_i, zero_i)

    def step(self, key, state: EpisodeStatsState, action, params=None):
        obs, env_state, reward, terminated, truncated, info = self._env.step(
            key, state.env_state, action, params
        )
        done = jnp.logical_or(terminated, truncated)
        ep_ret = state.episode_return + reward.astype(jnp.float32)
        ep_len = state.episode_length + 1
        new = EpisodeStatsState(
            env_state=env_state,
            episode_return=jnp.where(done, 0.0, ep_ret),
            episode_length=jnp.where(done, 0, ep_len),
            returned_episode_return=jnp.where(done, ep_ret, state.returned_episode_return),
            returned_episode_length=jnp.where(done, ep_len, state.returned_episode_length),
            episodes_done=state.episodes_done + done.astype(jnp.int32),
        )
        info = dict(info)
        info["episode_return"] = new.returned_episode_return
        info["episode_length"] = new.returned_episode_length
        info["returned_episode"] = done
        info["episodes_done"] = new.episodes_done
        return obs, new, reward, terminated, truncated, info


class LegacyGymnaxStep(EnvWrapper):
    """An smjax environment for trainers of the pre-1.0 gymnax API (rejax, PureJaxRL)::

        env = LegacyGymnaxStep(*smjax.make("craft/get_wood", max_steps=50))
        algo = rejax.PPO.create(env=env, env_params=env.default_params, ...)

    ``step`` returns (obs, state, reward, done, info) with ``info["truncated"]``; spaces are
    gymnax's classes when gymnax is installed; ``default_params`` (the params given, else
    the environment's, as ``gymnax_params``) carries ``max_steps_in_episode``, and the
    environment's own params are accepted too.
    """

    def __init__(self, env: Environment, params=None):
        super().__init__(env)
        self._params = env.default_params if params is None else unwrap_params(params)

    @property
    def default_params(self):
        return gymnax_params(self._params)

    def reset(self, key, params=None):
        return self._env.reset(key, unwrap_params(params))

    def step(self, key, state, action, params=None):
        obs, state, reward, terminated, truncated, info = self._env.step(
            key, state, action, unwrap_params(params))
        info = dict(info)
        info["truncated"] = truncated
        return obs, state, reward, jnp.logical_or(terminated, truncated), info

    def action_space(self, params=None):
        return to_gymnax_space(self._env.action_space(unwrap_params(params)))

    def observation_space(self, params=None):
        return to_gymnax_space(self._env.observation_space(unwrap_params(params)))

    @property
    def num_actions(self) -> int:
        return self._env.action_space(self._env.default_params).n
