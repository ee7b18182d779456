"""Fetch & Stack: success rate of the fully scripted hierarchy, and env steps per second.

    python benchmarks/fetch_scripted.py --num-blocks 3 --num-envs 1 32 --steps 20 --episodes 64

On the 2-core CPU, batches of 64 three-block environments hung inside XLA:CPU (every
thread waiting, no progress, reproducible; 32 run fine, and so did 64 two-block ones),
hence the CPU defaults of 32 environments and success episodes run in chunks of 32. On a
GPU pass e.g. ``--num-envs 1024 8192 --chunk 1024``.

For each --num-envs value it prints one JSON line with the throughput of
``jit(vmap(scan(step_env)))`` (``--policy scripted`` (default): the scripted hierarchy
picks the actions; ``random``: uniform actions; ``--steps`` steps per environment;
compile time measured separately, steps/s = num_envs * steps / run time, median of
``--repeats``). Then it plays ``--episodes`` full episodes (50 N steps) of the scripted
hierarchy (``--levels 2``: stack -> place_i -> reach/pick/release, the paper's hierarchy;
``--levels 1``: stack -> place_i controllers) and prints the success rate: the fraction
of episodes whose final state has every block within 0.04 m of its goal. ``--epsilon 0 0.05``
repeats the episodes with a root that explores (a random block's ``place_i`` with that
probability at each level-1 choice).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import smjax
from smjax.envs.fetch.scripted import rollout


def throughput(env, params, num_envs: int, steps: int, repeats: int, seed: int,
               policy: str = "scripted") -> dict:
    def one_env(key):
        if policy == "scripted":
            return rollout(env, key, params, steps, levels=2)[1]
        key_reset, key_run = jax.random.split(key)
        _, state = env.reset_env(key_reset, params)

        def tick(state, k):
            action = jax.random.uniform(k, (4,), minval=-1.0, maxval=1.0)
            _, state, reward, *_ = env.step_env(k, state, action, params)
            return state, reward

        _, rewards = jax.lax.scan(tick, state, jax.random.split(key_run, steps))
        return rewards

    # Random actions at 64 environments hung inside XLA:CPU on the 2-core test machine
    # (all threads waiting, no progress; not investigated further), so the default policy
    # is the scripted hierarchy, which is also the workload of template execution.
    def run(key):
        return jax.vmap(one_env)(jax.random.split(key, num_envs))

    fn = jax.jit(run)
    t0 = time.perf_counter()
    jax.block_until_ready(fn(jax.random.PRNGKey(seed)))
    compile_s = time.perf_counter() - t0
    times = []
    for r in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(jax.random.PRNGKey(seed + 1 + r)))
        times.append(time.perf_counter() - t0)
    # The timed call also resets num_envs environments once; that is one extra step's worth.
    return {"env": env.name, "policy": policy, "num_envs": num_envs, "steps": steps,
            "steps_per_second": num_envs * steps / statistics.median(times),
            "compile_seconds": compile_s, "device": jax.devices()[0].platform}


def scripted_success(env, params, episodes: int, levels: int, seed: int, chunk: int,
                     epsilon: float = 0.0) -> dict:
    horizon = int(params.max_steps)
    fn = jax.jit(jax.vmap(lambda k: rollout(env, k, params, horizon, levels, epsilon)))
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    successes, scores = [], []
    t0 = time.perf_counter()
    for start in range(0, episodes, chunk):  # equal-sized chunks reuse one compiled program
        batch = keys[start:start + chunk]
        if batch.shape[0] < chunk:
            batch = jnp.concatenate([batch, keys[:chunk - batch.shape[0]]])
        _, _, info = fn(batch)
        take = min(chunk, episodes - start)
        successes.append(np.asarray(info["is_success"])[:take])
        scores.append(np.asarray(info["score"])[:take])
    seconds = time.perf_counter() - t0
    success, score = np.concatenate(successes), np.concatenate(scores)
    first = [int(np.argmax(s)) for s in success if s.any()]
    return {"env": env.name, "levels": levels, "epsilon": epsilon, "episodes": episodes,
            "horizon": horizon,
            "success_rate": float(success[:, -1].mean()),
            "ever_success_rate": float(success.any(axis=1).mean()),
            "final_score": float(score[:, -1].mean()),
            "median_steps_to_first_success": float(np.median(first)) if first else None,
            "seconds_with_compile": seconds}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--num-blocks", type=int, default=3)
    ap.add_argument("--num-envs", type=int, nargs="+", default=[1, 32])
    ap.add_argument("--chunk", type=int, default=32,
                    help="environments per compiled batch for the success-rate episodes")
    ap.add_argument("--steps", type=int, default=20, help="env steps per throughput run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--policy", choices=("scripted", "random"), default="scripted",
                    help="actions for the throughput runs")
    ap.add_argument("--episodes", type=int, default=64, help="scripted episodes (0: skip)")
    ap.add_argument("--levels", type=int, choices=(1, 2), default=2)
    ap.add_argument("--epsilon", type=float, nargs="+", default=[0.0],
                    help="level-1 exploration rate(s) of the success episodes: the score an "
                         "optimal root reaches while exploring like DQN (its end epsilon: 0.05)")
    ap.add_argument("--substeps", type=int, default=None)
    ap.add_argument("--timestep", type=float, default=None)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    overrides = {"num_blocks": args.num_blocks}
    if args.substeps is not None:
        overrides["substeps"] = args.substeps
    if args.timestep is not None:
        overrides["timestep"] = args.timestep
    env, params = smjax.make(f"fetch/stack{args.num_blocks}", **overrides)
    for n in args.num_envs:
        if args.steps > 0:
            print(json.dumps(throughput(env, params, n, args.steps, args.repeats, args.seed,
                                        args.policy)), flush=True)
    for epsilon in args.epsilon if args.episodes > 0 else []:
        print(json.dumps(scripted_success(env, params, args.episodes, args.levels, args.seed,
                                          min(args.chunk, args.episodes), epsilon)), flush=True)


if __name__ == "__main__":
    main()
