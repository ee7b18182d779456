"""Throughput of ``jit(vmap(env.step))`` with random actions.

    python -m smjax.envs.craft.bench --task get_gem --obs paper none --num-envs 1 64 1024 4096

Each measurement: a jitted ``lax.scan`` of ``--steps`` steps over ``num_envs`` environments
(random actions drawn inside the scan), compiled and run once to warm up, then timed
``--repeats`` times; the median is reported. Prints one JSON line per (obs, num_envs).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import jax
import jax.numpy as jnp

from smjax.envs.craft.env import make_craft


def measure(task: str, obs: str, num_envs: int, steps: int, repeats: int = 3,
            auto_reset: bool = True) -> dict:
    env, params = make_craft(task, observation=obs)
    step_fn = env.step if auto_reset else env.step_env
    vstep = jax.vmap(step_fn, in_axes=(0, 0, 0, None))

    def run(key):
        keys = jax.random.split(key, num_envs)
        obs0, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)

        def body(carry, _):
            state, key, acc, _ = carry
            key, k_act, k_step = jax.random.split(key, 3)
            actions = jax.random.randint(k_act, (num_envs,), 0, 5)
            obs, state, reward, term, trunc, _ = vstep(
                jax.random.split(k_step, num_envs), state, actions, params
            )
            # The observation rides in the carry, so every step materialises all of it (as
            # a rollout buffer or a network input would); the rewards are summed.
            return (state, key, acc + reward.sum(), obs), None

        carry = (state, key, jnp.float32(0), obs0)
        (state, _, acc, obs), _ = jax.lax.scan(body, carry, None, length=steps)
        return acc + jnp.sum(obs, dtype=jnp.float32)

    fn = jax.jit(run)
    t0 = time.perf_counter()
    fn(jax.random.PRNGKey(0)).block_until_ready()
    compile_s = time.perf_counter() - t0
    times = []
    for r in range(repeats):
        t0 = time.perf_counter()
        fn(jax.random.PRNGKey(r + 1)).block_until_ready()
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    return {"task": task, "obs": obs, "num_envs": num_envs, "steps": steps,
            "auto_reset": auto_reset, "steps_per_second": num_envs * steps / med,
            "median_seconds": med, "first_call_seconds": compile_s,
            "device": jax.devices()[0].platform}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="get_gem")
    ap.add_argument("--obs", nargs="+", default=["paper", "none"])
    ap.add_argument("--num-envs", nargs="+", type=int, default=[1, 64, 1024, 4096, 16384])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-reset", action="store_true", help="time step_env (no auto-reset)")
    args = ap.parse_args(argv)
    for obs in args.obs:
        for n in args.num_envs:
            print(json.dumps(measure(args.task, obs, n, args.steps, args.repeats,
                                     auto_reset=not args.no_reset)), flush=True)


if __name__ == "__main__":
    main()
