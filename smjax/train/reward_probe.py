"""Why a run went non-finite: a short random rollout that looks for non-finite rewards.

A NaN reward reaches the learner's returns and then its parameters; the run then sees
only non-finite parameters, which would otherwise be blamed on the learning rate. Run
only after a failure (it compiles one small program).
"""
from __future__ import annotations

from typing import Any

import jax
import numpy as np


def _random_rewards(env, params, num_envs: int, steps: int, seed: int) -> np.ndarray:
    """[steps, num_envs] rewards of random play."""
    space = env.action_space(params)
    reset = jax.vmap(env.reset, in_axes=(0, None))
    step = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    @jax.jit
    def play(key):
        key_reset, key_run = jax.random.split(key)
        _, state = reset(jax.random.split(key_reset, num_envs), params)

        def body(state, k):
            key_act, key_step = jax.random.split(k)
            actions = jax.vmap(space.sample)(jax.random.split(key_act, num_envs))
            out = step(jax.random.split(key_step, num_envs), state, actions, params)
            return out[1], out[2]

        return jax.lax.scan(body, state, jax.random.split(key_run, steps))[1]

    return np.asarray(play(jax.random.PRNGKey(seed)))


def nonfinite_reward(env, params: Any, num_envs: int = 16, steps: int = 128,
                     seed: int = 0) -> str | None:
    """A sentence naming a non-finite reward random play meets, else None."""
    try:
        rewards = _random_rewards(env, params, num_envs, steps, seed)
    except Exception:  # noqa: BLE001 - a diagnosis must never hide the original error
        return None
    bad = ~np.isfinite(rewards)
    if not bad.any():
        return None
    t, i = np.argwhere(bad)[0]
    name = getattr(env, "name", type(env).__name__)
    return (f"the environment {name} returns non-finite rewards ({rewards[t, i]} at step {t} "
            f"of random play, env {i}; {int(bad.sum())} of {bad.size}): fix its reward "
            f"(smjax.testing.check_env names it)")
