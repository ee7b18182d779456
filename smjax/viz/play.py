"""Frames of an episode to render: a uniformly random policy's (a saved policy renders its
own: ``SavedPolicy.render``)."""
from __future__ import annotations

import jax
import numpy as np

from smjax.core.registry import make


def random_frames(task: str, *, steps: int = 100, seed: int = 0,
                  env_overrides: dict | None = None) -> list[np.ndarray]:
    """RGB frames of ``steps`` steps of uniformly random actions in one environment of
    ``task`` (auto-reset: an episode that ends goes on with the next)."""
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
    return [np.asarray(env.render(s, params), np.uint8) for s in states]
