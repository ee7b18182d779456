"""One seed's joint fine-tuning update on a CPU: one program over every option, against
two programs, each over part of the options, called at once from two threads.

With one seed left on a 2-core CPU, one core idles; the options' updates are independent
of each other, so two programs could share them out. This times that route on one recorded
joint rollout (``joint_update_cost``'s), before anything is built for it.

    JAX_PLATFORMS=cpu python benchmarks/lone_seed_update_split.py --env observation=compact
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import joint_update_cost as J  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="craft/get_gem")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    from smjax.agents.option_batch import OptionBatch, joint_batch

    spec = argparse.Namespace(algo="ppo", task=args.task, env=args.env, num_envs=128,
                              rollout_ticks=32, updates=4)
    engine, _ = J.build(spec, {"option_update": "grouped"})
    O = engine.h.num_options
    state = J.joint_state(engine, 1)
    traj = J.record_rollout(engine, state, jnp.ones((1, O), bool))
    first = lambda tree: jax.tree.map(lambda x: x[0], tree)  # noqa: E731  (the one seed)
    learners = first(state.learner)
    batch, _ = joint_batch(first(state.carry.pending), first(traj))
    update, key = engine.agent.update_options, jax.random.PRNGKey(5)

    def over(options):
        idx = jnp.asarray(options)

        def part(learners, batch, key):
            learners = jax.tree.map(lambda x: x[idx], learners)
            traj = jax.tree.map(lambda x: None if x is None else x[idx], batch.traj)
            return update(learners, OptionBatch(batch.obs, traj), key)[0]
        return jax.jit(part)

    whole = over(list(range(O)))
    halves = [over(list(range(O // 2 + 1))), over(list(range(O // 2 + 1, O)))]

    def one_program():
        jax.block_until_ready(whole(learners, batch, key))

    def two_programs():
        threads = [threading.Thread(target=lambda p=p: jax.block_until_ready(
            p(learners, batch, key))) for p in halves]
        [t.start() for t in threads]
        [t.join() for t in threads]

    ways = {"one program": one_program, "two programs on two threads": two_programs}
    times = {name: [] for name in ways}
    for fn in ways.values():  # compile
        fn()
    for _ in range(args.repeats):  # alternating
        for name, fn in ways.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    for name, ts in times.items():
        print(f"{name:30s} median {statistics.median(ts) * 1e3:7.1f} ms of {len(ts)}")
    print(f"{args.task} {args.env} options {O}, split {O // 2 + 1} + {O - O // 2 - 1}, "
          f"{jax.default_backend()}")


if __name__ == "__main__":
    main()
