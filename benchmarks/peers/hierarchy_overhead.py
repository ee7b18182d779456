"""The option hierarchy's own overhead: a Craft top-down training chunk vs a flat one.

Builds ``smjax.train.engine.Engine`` for ``craft/get_gem`` twice at the same
``num_envs``/``rollout_ticks`` and times one compiled chunk (``updates_per_chunk`` x
(rollout + PPO update)) of each, called exactly as ``HierarchyTrainer`` calls it:

* top-down, level 2: hierarchy "paper", the root ``get_gem`` already learned (frozen,
  sampling from its bank entry), ``give_axe`` is the learner, episodes start at the
  root, teleports on (the Engine's training runner always allows them);
* flat: hierarchy "flat", its single option (the root over primitives) is the learner.

A third row, for reference, is ``smjax.agents.flat_train`` on the same environment
(plain PPO on primitives without the option runner). Compile is timed separately;
the median of ``--repeats`` chunk runs is reported, and the ratio top-down/flat
(target <= 1.5)::

    python benchmarks/peers/hierarchy_overhead.py --num-envs 128 --rollout-ticks 32
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def time_engine_chunk(env, params, hierarchy, cfg, learner_name: str, learned_names, seeds, repeats: int) -> dict:
    """Compile and time ``Engine.chunk`` as the trainer calls it (state donated, so chained)."""
    from smjax.agents import make_agent
    from smjax.train.engine import ChunkControls, Engine, SeedState

    engine = Engine(env, params, hierarchy, make_agent(cfg.algo, **cfg.agent), cfg)
    num_seeds = len(seeds)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds, jnp.uint32))
    split = jax.vmap(lambda k: jax.random.split(k, 3))(keys)
    learner = engine.init_learner(split[:, 0])
    start = jnp.zeros((num_seeds,), jnp.int32)  # top-down: every episode starts at the root
    state = SeedState(engine.reset(split[:, 1], start), learner, split[:, 2])
    bank = engine.new_bank(learner)
    learned = jnp.zeros((num_seeds, hierarchy.num_options), bool)
    for name in learned_names:
        learned = learned.at[:, hierarchy.option_index(name)].set(True)
    learner_id = jnp.full((num_seeds,), hierarchy.option_index(learner_name), jnp.int32)
    active = jnp.ones((num_seeds,), bool)
    # a level's per-seed switches: teleports on, episodes reset with the learner's option,
    # no side costs, the run's discount (the running-success windows are left out)
    tick = ChunkControls(learner_id, start, jnp.ones((num_seeds,), bool),
                         jnp.zeros((num_seeds,), bool), jnp.zeros((num_seeds,), jnp.float32),
                         jnp.full((num_seeds,), cfg.gamma, jnp.float32))
    args = (active, bank, learned, tick)
    t0 = time.perf_counter()
    compiled = engine.chunk.lower(state, *args).compile()
    compile_s = time.perf_counter() - t0
    runs = []
    decisions = 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        state, stats, metrics = compiled(state, *args)[:3]
        jax.block_until_ready(state)
        runs.append(time.perf_counter() - t0)
        decisions = int(jnp.sum(metrics["decisions"]))
    ticks = num_seeds * cfg.num_envs * cfg.rollout_ticks * cfg.updates_per_chunk
    med = statistics.median(runs)
    return {"compile_s": compile_s, "run_s": runs, "median_s": med, "env_ticks": ticks,
            "ticks_per_s": ticks / med, "learner_decisions_last_chunk": decisions,
            "env_episodes_last_chunk": int(jnp.sum(stats.env_episodes))}


def time_flat_train(env, params, cfg, repeats: int) -> dict:
    from smjax.agents import make_agent
    from smjax.agents.flat_train import FlatTrainConfig, make_train

    flat_cfg = FlatTrainConfig(num_envs=cfg.num_envs, num_steps=cfg.rollout_ticks,
                               num_updates=cfg.updates_per_chunk, gamma=cfg.gamma)
    train = make_train(flat_cfg, env, params, make_agent(cfg.algo, **cfg.agent))
    timing = _common.compile_and_time(lambda k: train(k)[1]["episodes"], (jax.random.PRNGKey(0),), repeats)
    timing.pop("output")
    ticks = cfg.num_envs * cfg.rollout_ticks * cfg.updates_per_chunk
    return dict(timing, env_ticks=ticks, ticks_per_s=ticks / timing["median_s"])


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="craft/get_gem")
    p.add_argument("--observation", default="paper", choices=["paper", "compact"])
    p.add_argument("--num-envs", type=int, default=128)
    p.add_argument("--rollout-ticks", type=int, default=32)
    p.add_argument("--updates-per-chunk", type=int, default=4)
    p.add_argument("--seeds", type=int, default=1, help="seeds vmapped in one chunk")
    p.add_argument("--learner", default="give_axe", help="option trained in the top-down chunk")
    p.add_argument("--algo", default="ppo", choices=["ppo", "dqn", "actor-critic"])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--no-flat-train", action="store_true", help="skip the flat_train reference row")
    p.add_argument("--json", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "hierarchy_overhead.json"))
    args = p.parse_args(argv)

    import smjax
    import smjax.envs  # noqa: F401  (registers the environments)
    from smjax.train.config import TrainConfig

    env, params = smjax.make(args.task, observation=args.observation)
    hierarchies = env.hierarchies()
    if "paper" not in hierarchies or "flat" not in hierarchies:
        raise ValueError(f"{args.task} needs 'paper' and 'flat' hierarchies; it has {', '.join(hierarchies)}")
    paper = hierarchies["paper"]
    if args.learner not in paper.learnable or args.learner == paper.learnable[0]:
        raise ValueError(f"--learner must be a non-root learnable option of 'paper': {', '.join(paper.learnable[1:])}")
    seeds = list(range(args.seeds))
    common = dict(algo=args.algo, num_envs=args.num_envs, rollout_ticks=args.rollout_ticks,
                  updates_per_chunk=args.updates_per_chunk)
    # Everything between the root and the learner is already learned in top-down order.
    above = [n for n in paper.learnable if paper.level(n) < paper.level(args.learner)]
    rows = {
        f"top-down level {paper.level(args.learner)} ({args.learner} learns, {', '.join(above)} frozen)":
            time_engine_chunk(env, params, paper, TrainConfig(method="top-down", hierarchy="paper", **common),
                              args.learner, above, seeds, args.repeats),
        "flat hierarchy (root learns on primitives)":
            time_engine_chunk(env, params, hierarchies["flat"], TrainConfig(method="flat", **common),
                              hierarchies["flat"].learnable[0], [], seeds, args.repeats),
    }
    if not args.no_flat_train and args.seeds == 1:
        rows["flat_train (no option runner, reference)"] = time_flat_train(env, params, TrainConfig(**common), args.repeats)
    names = list(rows)
    ratio = rows[names[0]]["median_s"] / rows[names[1]]["median_s"]
    _common.print_table(["chunk", "median s", "env ticks/s", "compile s"],
                        [[n, r["median_s"], r["ticks_per_s"], r["compile_s"]] for n, r in rows.items()])
    print(f"ratio top-down / flat hierarchy chunk time: {ratio:.2f} (target <= 1.5)")
    summary = {"benchmark": "hierarchy_overhead", "config": {k: v for k, v in vars(args).items() if k != "json"},
               "machine": _common.machine(), "versions": _common.versions("smjax"), "results": rows,
               "ratio_top_down_over_flat": ratio}
    _common.write_json(args.json, summary)
    print(json.dumps({"benchmark": "hierarchy_overhead", "loadavg": summary["machine"]["loadavg_1_5_15"],
                      "ticks_per_s": {n: round(r["ticks_per_s"]) for n, r in rows.items()},
                      "ratio_top_down_over_flat": round(ratio, 3)}))
    return summary


if __name__ == "__main__":
    main()
