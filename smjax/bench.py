"""Environment throughput: ``smjax bench ENV/TASK --num-envs N --steps T``.

Steps a batch of environments with uniformly random actions inside one ``lax.scan``
(auto-reset included) and reports the median steps per second over several timed
repeats; compilation is timed separately.
"""
from __future__ import annotations

import statistics
import time

import jax
import jax.numpy as jnp

from smjax.core.registry import make
from smjax.train.bounds import MAX_ENVS

MAX_STEPS = 10_000_000  # the scan's length is an int32, and each step is a full batch
MAX_REPEATS = 1000


def make_rollout(env, params, num_envs: int, steps: int):
    space = env.action_space(params)
    step = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def rollout(key):
        k_reset, k_run = jax.random.split(key)
        _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, num_envs), params)

        def body(carry, key):
            state, acc = carry
            k_act, k_step = jax.random.split(key)
            actions = jax.vmap(space.sample)(jax.random.split(k_act, num_envs))
            obs, state, reward, term, trunc, _ = step(jax.random.split(k_step, num_envs), state, actions, params)
            # fold outputs into a scalar so nothing is dead-code eliminated
            acc = acc + reward.sum() + term.sum() + jnp.asarray(obs, jnp.float32).reshape(num_envs, -1)[:, 0].sum()
            return (state, acc), None

        (state, acc), _ = jax.lax.scan(body, (state, jnp.zeros(())), jax.random.split(k_run, steps))
        return acc

    return jax.jit(rollout)


def bench(task: str, num_envs: int, steps: int, repeats: int = 3, **overrides) -> dict:
    for name, value, high in (("num_envs", num_envs, MAX_ENVS), ("steps", steps, MAX_STEPS),
                              ("repeats", repeats, MAX_REPEATS)):
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= high:
            raise ValueError(f"bench {name} must be an integer in [1, {high}], got {value!r}")
    env, params = make(task, **overrides)
    rollout = make_rollout(env, params, num_envs, steps)
    key = jax.random.PRNGKey(0)
    t0 = time.perf_counter()
    compiled = rollout.lower(key).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(key))  # warm-up
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(jax.random.PRNGKey(i + 1)))
        times.append(time.perf_counter() - t0)
    median = statistics.median(times)
    return {
        "env": task, "num_envs": num_envs, "steps": steps,
        "steps_per_second": num_envs * steps / median,
        "compile_seconds": compile_s, "device": jax.devices()[0].platform,
        "device_kind": jax.devices()[0].device_kind, "repeats": repeats,
        "overrides": overrides,
    }
