"""Adapters that present other JAX environment libraries through the smjax protocol.

``from_gymnax(gymnax_env, gymnax_params)`` wraps a gymnax environment so that smjax's
learners (``smjax.agents.flat_train.make_train``) and wrappers run on it unchanged::

    import gymnax
    from smjax.core.adapters import from_gymnax
    env, params = from_gymnax(*gymnax.make("CartPole-v1"))
    obs, state = env.reset(key, params)
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)

gymnax's own ``step`` auto-resets, so the adapter builds smjax's ``reset_env``/``step_env``
from gymnax's ``reset_env``/``step_env`` (which do not) and lets smjax's base class add
the auto-reset. Two gymnax generations are supported:

* gymnax >= 1.0: ``step_env`` returns ``(obs, state, reward, terminated, info)`` and the
  time limit is ``env.is_truncated(state, params)``; the split is exact.
* gymnax 0.0.x: ``step_env`` returns ``(obs, state, reward, done, info)`` where ``done``
  already includes the time limit. The adapter reports ``truncated = done and the time
  limit is reached`` and ``terminated = done and not truncated``, which needs
  ``state.time`` and ``params.max_steps_in_episode`` (all built-in gymnax environments
  have both). A natural termination on exactly the last allowed step is therefore
  reported as a truncation: gymnax 0.0.x does not expose the information to tell them
  apart. Environments without those fields report every ``done`` as a termination.
"""
from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from smjax.core import spaces
from smjax.core.env import Environment, StepResult


def _has_gymnax() -> bool:
    try:
        import gymnax  # noqa: F401
    except ImportError:
        return False
    return True


def convert_space(space: Any) -> spaces.Space:
    """A gymnax space as the equivalent smjax space (Discrete and Box; Dict/Tuple raise)."""
    kind = type(space).__name__
    if kind == "Discrete":
        return spaces.Discrete(int(space.n), dtype=jnp.int32)
    if kind == "Box":
        return spaces.Box(space.low, space.high, tuple(space.shape), space.dtype)
    raise ValueError(
        f"cannot convert gymnax space {kind} ({space!r}); supported spaces: Discrete, Box")


class GymnaxEnvironment(Environment):
    """A gymnax environment seen through the smjax ``Environment`` protocol.

    ``reward`` is float32, ``terminated``/``truncated`` are bool scalars; the gymnax
    ``info`` dict is passed through (with gymnax 0.0.x's combined flag kept as
    ``info["gymnax_done"]``). The task's success is the episode return, on no known scale
    (``success_unbounded``): smjax's trainer ends no root level at a threshold on it.
    """

    success_unbounded = True

    def __init__(self, gymnax_env: Any, gymnax_params: Any):
        for method in ("reset_env", "step_env", "action_space", "observation_space"):
            if not callable(getattr(gymnax_env, method, None)):
                raise ValueError(
                    f"from_gymnax needs a gymnax Environment with reset_env, step_env, "
                    f"action_space and observation_space; {type(gymnax_env).__name__} "
                    f"has no {method}")
        self.gymnax_env = gymnax_env
        self._params = gymnax_params
        self.name = f"gymnax/{getattr(gymnax_env, 'name', type(gymnax_env).__name__)}"
        # gymnax >= 1.0 has a separate time-limit predicate; 0.0.x folds it into done.
        self._exact_truncation = callable(getattr(type(gymnax_env), "is_truncated", None))

    @property
    def default_params(self) -> Any:
        return self._params

    def reset_env(self, key: jax.Array, params: Any) -> tuple[jax.Array, Any]:
        return self.gymnax_env.reset_env(key, params)

    def _time_limit_reached(self, state: Any, params: Any) -> jax.Array | None:
        time = getattr(state, "time", None)
        limit = getattr(params, "max_steps_in_episode", None)
        if time is None or limit is None:
            return None
        return jnp.asarray(time >= limit)

    def step_env(self, key: jax.Array, state: Any, action: jax.Array, params: Any) -> StepResult:
        obs, next_state, reward, flag, info = self.gymnax_env.step_env(key, state, action, params)
        flag = jnp.asarray(flag, bool)
        info = dict(info)
        if self._exact_truncation:
            terminated = flag
            truncated = jnp.logical_and(
                jnp.asarray(self.gymnax_env.is_truncated(next_state, params), bool),
                jnp.logical_not(terminated))
        else:
            info["gymnax_done"] = flag
            time_up = self._time_limit_reached(next_state, params)
            if time_up is None:
                terminated, truncated = flag, jnp.zeros_like(flag)
            else:
                truncated = jnp.logical_and(flag, time_up)
                terminated = jnp.logical_and(flag, jnp.logical_not(time_up))
        reward = jnp.asarray(reward, jnp.float32).reshape(())  # some gymnax envs return shape (1,)
        return obs, next_state, reward, terminated, truncated, info

    def get_obs(self, state: Any, params: Any) -> jax.Array:
        return self.gymnax_env.get_obs(state, params)

    def action_space(self, params: Any | None = None) -> spaces.Space:
        return convert_space(self.gymnax_env.action_space(self._params if params is None else params))

    def observation_space(self, params: Any | None = None) -> spaces.Space:
        return convert_space(
            self.gymnax_env.observation_space(self._params if params is None else params))

    def render(self, state: Any, params: Any | None = None):
        raise NotImplementedError(
            "gymnax environments render through gymnax.visualize, not an RGB array")


def from_gymnax(gymnax_env: Any, gymnax_params: Any | None = None) -> tuple[GymnaxEnvironment, Any]:
    """Wrap a gymnax environment: returns ``(smjax Environment, params)``.

    ``gymnax_params=None`` uses the environment's ``default_params``. Accepts a
    gymnax ``make`` result unpacked: ``from_gymnax(*gymnax.make("CartPole-v1"))``.
    """
    if isinstance(gymnax_env, str):
        if not _has_gymnax():
            raise ImportError("from_gymnax with an id needs gymnax: pip install 'smjax[peers]'")
        import gymnax

        if gymnax_env not in gymnax.registered_envs:
            raise KeyError(f"unknown gymnax id {gymnax_env!r}; valid ids: {', '.join(gymnax.registered_envs)}")
        gymnax_env, made_params = gymnax.make(gymnax_env)
        gymnax_params = made_params if gymnax_params is None else gymnax_params
    env = GymnaxEnvironment(gymnax_env, gymnax_params)  # validates before default_params is read
    if gymnax_params is None:
        gymnax_params = gymnax_env.default_params
        env._params = gymnax_params
    return env, gymnax_params


# ---- the other direction: smjax environments for gymnax-API trainers (rejax, PureJaxRL) ---
@struct.dataclass
class GymnaxParams:
    """An environment's params as gymnax trainers read them: rejax evaluates for
    ``env_params.max_steps_in_episode`` steps. Other fields are the environment's."""

    env_params: Any
    max_steps_in_episode: int = struct.field(pytree_node=False, default=1000)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name == "env_params":  # copy/pickle probe dunders
            raise AttributeError(name)
        return getattr(self.env_params, name)


def gymnax_params(params: Any, max_steps_in_episode: int | None = None) -> GymnaxParams:
    """``params`` for a gymnax trainer; the episode cap defaults to ``params.max_steps``."""
    if isinstance(params, GymnaxParams):
        return params
    limit = max_steps_in_episode if max_steps_in_episode is not None else \
        getattr(params, "max_steps", None)
    if limit is None:
        raise ValueError("these params have no max_steps: pass max_steps_in_episode")
    return GymnaxParams(params, int(limit))


def unwrap_params(params: Any) -> Any:
    return params.env_params if isinstance(params, GymnaxParams) else params


def to_gymnax_space(space: spaces.Space) -> Any:
    """A smjax space as gymnax's own class where gymnax is installed (trainers such as rejax
    choose a categorical or Gaussian policy by ``isinstance`` on it), else unchanged."""
    if not _has_gymnax():
        return space
    from gymnax.environments import spaces as gspaces

    if isinstance(space, spaces.Discrete) and space.shape == ():
        return gspaces.Discrete(space.n)
    if isinstance(space, spaces.Box):
        return gspaces.Box(space.low, space.high, space.shape, space.dtype)
    raise ValueError(f"no gymnax equivalent of {space!r} (Discrete with shape () and Box)")
