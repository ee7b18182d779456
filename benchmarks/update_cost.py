"""What one PPO update costs, memoryless against recurrent (``--agent recurrent_size``),
and a dense torso against a convolutional one (``--agent torso``).

A rollout of the shape training uses (``--ticks`` + 1 rows with the pending one, ``--envs``
environments, Craft's observation width) with a decision on every tick, updated by the
same jitted ``agent.update`` the engine calls; the sizes alternate, so a noisy machine
hits both alike. Prints the median seconds per update and the compile time of each.

    python benchmarks/update_cost.py --sizes 0 64 --repeats 5
    python benchmarks/update_cost.py --sizes 0 --torsos mlp conv --repeats 5
"""
from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp

import smjax
from smjax.agents import make_agent
from smjax.core.transition import Transition


def rollout(key, obs_shape, num_actions: int, ticks: int, envs: int, memory: int) -> Transition:
    k1, k2, k3 = jax.random.split(key, 3)
    shape = (ticks, envs)
    return Transition(
        obs=jax.random.bernoulli(k1, 0.05, shape + obs_shape).astype(jnp.uint8),
        action=jax.random.randint(k2, shape, 0, num_actions),
        action_mask=jnp.ones(shape + (num_actions,), bool),
        log_prob=jnp.full(shape, -jnp.log(num_actions)), value=jnp.zeros(shape),
        decision=jnp.ones(shape, bool),
        reward=jax.random.bernoulli(k3, 0.05, shape).astype(jnp.float32),
        discount=jnp.full(shape, 0.99), done=jnp.zeros(shape, bool).at[-1].set(True),
        hidden=jnp.zeros(shape + (memory,)) if memory else None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="craft/get_gem")
    ap.add_argument("--sizes", type=int, nargs="+", default=[0, 64],
                    help="recurrent_size values (0: memoryless)")
    ap.add_argument("--torsos", nargs="+", default=["mlp"], choices=["mlp", "conv"],
                    help="torso values (conv: over the observation's declared grids)")
    ap.add_argument("--ticks", type=int, default=33)
    ap.add_argument("--envs", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    env, params = smjax.make(args.task)
    obs, _ = env.reset(jax.random.PRNGKey(0), params)
    num_actions = 16
    runs = {}
    for size in args.sizes:
        for torso in args.torsos:
            agent = make_agent("ppo", layout=env.observation_layout(params), recurrent_size=size,
                               torso=torso)
            state = agent.init(jax.random.PRNGKey(1), obs, num_actions)
            traj = rollout(jax.random.PRNGKey(2), obs.shape, num_actions, args.ticks, args.envs,
                           size)
            update = jax.jit(agent.update)
            t0 = time.perf_counter()
            compiled = update.lower(state, traj, jax.random.PRNGKey(3)).compile()
            runs[size, torso] = (compiled, state, traj, time.perf_counter() - t0, [])
    for r in range(args.repeats):
        for compiled, state, traj, _, times in runs.values():
            t0 = time.perf_counter()
            jax.block_until_ready(compiled(state, traj, jax.random.PRNGKey(r)))
            times.append(time.perf_counter() - t0)
    first = next(iter(runs))
    base = statistics.median(runs[first][4])
    for (size, torso), (_, _, _, compile_s, times) in runs.items():
        med = statistics.median(times)
        print(f"recurrent_size {size:4d}, torso {torso}: update {med:.3f} s (median of "
              f"{len(times)}; {med / base:.2f}x of {first}), compile {compile_s:.1f} s, "
              f"obs {obs.size} wide, {args.ticks} x {args.envs} ticks")


if __name__ == "__main__":
    main()
