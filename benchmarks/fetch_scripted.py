"""Fetch & Stack: success rate of the fully scripted hierarchy, and env steps per second.

    python benchmarks/fetch_scripted.py --num-blocks 3 --num-envs 1 32 --steps 20 --episodes 64

On the 2-core CPU, batches of 64 three-block environments hung inside XLA:CPU (every
thread waiting, no progress, reproducible; 32 run fine, and so did 64 two-block ones),
hence the CPU defaults of 32 environments and success episodes run in chunks of 32. On a
GPU pass e.g. ``--num-envs 1024 8192 --chunk 1024``.

The scripted hierarchy is the catalogue's ``scripted`` one (``--levels 2``: stack ->
place_i -> reach/pick/release, the paper's hierarchy, every choice a scripted policy of
``smjax/envs/fetch/policies.py``) or ``scripted_root`` (``--levels 1``: stack -> place_i
controllers), played by the hierarchical runner itself (``HierarchyRunner`` without an
agent: nobody learns, nothing is learned, every decision is scripted).

For each --num-envs value it prints one JSON line with the throughput of ``--steps``
ticks per environment (``--policy scripted`` (default): the runner plays the scripted
hierarchy (``--levels``), so this includes the runner's tick; ``random``:
``jit(vmap(scan(step_env)))`` with uniform actions; compile time measured separately,
steps/s = num_envs * steps / run time, median of ``--repeats``). Then it plays
``--episodes`` full episodes (50 N steps) of the scripted hierarchy and prints the
success rate: the fraction of episodes whose final state has every block within 0.04 m of
its goal, and their mean final score. ``--epsilon 0 0.05`` repeats the episodes with a
root that explores (a random block's ``place_i`` with that probability at each of its
choices).
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
from smjax.envs.fetch.dynamics import score as fetch_score
from smjax.envs.fetch.templates import scripted_hierarchy
from smjax.options.runner import NO_OPTION, Controls, HierarchyRunner


def scripted_runner(env, params, levels: int = 2, epsilon: float = 0.0):
    """(runner, controls) that play the scripted hierarchy: no agent, no teleports."""
    h = scripted_hierarchy(env, levels, epsilon)
    runner = HierarchyRunner(env, params, h, None)
    controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0),
                        jnp.zeros((h.num_options,), bool), gamma=1.0, teleport=False)
    return runner, controls


def play(runner, controls, key: jax.Array, num_envs: int, ticks: int):
    """``ticks`` ticks of ``num_envs`` environments from resets (auto-reset by the runner).

    Returns (score [B, T], task_end [B, T]): the fraction of blocks in place after each
    tick (at an episode's last tick its reported score, 0 where physics diverged) and
    whether an episode ended there. Jit it (``num_envs`` and ``ticks`` static)."""
    n = runner.env.num_blocks
    k_reset, k_run = jax.random.split(key)
    carry = runner.reset(k_reset, controls, num_envs)

    def tick(c, k):
        c, tr, ends = runner.tick(c, k, None, None, controls)
        # nobody learns: the root's reward is the environment's, -(blocks not in place)
        score = jnp.where(ends.reset, ends.task_success, fetch_score(tr.reward, n))
        return c, (score, ends.task_end)

    _, (score, end) = jax.lax.scan(tick, carry, jax.random.split(k_run, ticks))
    return score.T, end.T


def throughput(env, params, num_envs: int, steps: int, repeats: int, seed: int,
               policy: str = "scripted", levels: int = 2) -> dict:
    if policy == "scripted":
        runner, controls = scripted_runner(env, params, levels)

        def run(key):
            return play(runner, controls, key, num_envs, steps)[0]
    else:
        def one_env(key):
            key_reset, key_run = jax.random.split(key)
            _, state = env.reset_env(key_reset, params)

            def tick(state, k):
                action = jax.random.uniform(k, (4,), minval=-1.0, maxval=1.0)
                _, state, reward, *_ = env.step_env(k, state, action, params)
                return state, reward

            _, rewards = jax.lax.scan(tick, state, jax.random.split(key_run, steps))
            return rewards

        # Random actions at 64 environments hung inside XLA:CPU on the 2-core test machine
        # (all threads waiting, no progress; not investigated further), so the default
        # policy is the scripted hierarchy, which is also the workload of template execution.
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


def first_episodes(score: np.ndarray, end: np.ndarray) -> dict:
    """Per environment, its first episode's final score, whether it ended with every
    block in place, whether it ever had them all in place, and when that first happened
    (score, end: [B, T]; an environment whose episode never ended counts its last tick;
    ``first`` is -1 where it never had them all)."""
    T = score.shape[1]
    last = np.where(end.any(1), np.argmax(end, 1), T - 1)
    final = score[np.arange(score.shape[0]), last]
    within = np.arange(T)[None, :] <= last[:, None]
    stacked = (score >= 1.0) & within
    first = np.where(stacked.any(1), np.argmax(stacked, 1), -1)
    return {"final": final, "success": final >= 1.0, "ever": stacked.any(1), "first": first}


def scripted_success(env, params, episodes: int, levels: int, seed: int, chunk: int,
                     epsilon: float = 0.0) -> dict:
    horizon = int(params.max_steps)
    runner, controls = scripted_runner(env, params, levels, epsilon)
    fn = jax.jit(lambda k: play(runner, controls, k, chunk, horizon))
    finals, successes, evers, firsts = [], [], [], []
    t0 = time.perf_counter()
    for c, start in enumerate(range(0, episodes, chunk)):  # equal chunks: one compiled program
        score, end = fn(jax.random.fold_in(jax.random.PRNGKey(seed), c))
        out = first_episodes(np.asarray(score), np.asarray(end))
        take = min(chunk, episodes - start)
        finals.append(out["final"][:take]), successes.append(out["success"][:take])
        evers.append(out["ever"][:take]), firsts.append(out["first"][:take])
    seconds = time.perf_counter() - t0
    firsts = np.concatenate(firsts)
    firsts = firsts[firsts >= 0]
    return {"env": env.name, "levels": levels, "epsilon": epsilon, "episodes": episodes,
            "horizon": horizon,
            "success_rate": float(np.concatenate(successes).mean()),
            "ever_success_rate": float(np.concatenate(evers).mean()),
            "final_score": float(np.concatenate(finals).mean()),
            "median_steps_to_first_success": float(np.median(firsts)) if firsts.size else None,
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
                                        args.policy, args.levels)), flush=True)
    for epsilon in args.epsilon if args.episodes > 0 else []:
        print(json.dumps(scripted_success(env, params, args.episodes, args.levels, args.seed,
                                          min(args.chunk, args.episodes), epsilon)), flush=True)


if __name__ == "__main__":
    main()
