"""What joint fine-tuning's update costs: one learner per option over every row, against
every option at once on its own decisions (``Agent.update_options``).

Builds the trainer's ``Engine`` for a task (the CLI's shapes: seeds x envs x ticks x
updates), records one joint rollout per seed (every option learned, exploring through
its own learner), and times, as compiled, seed-vmapped programs on the same inputs:

* ``update``: one joint update, three ways: ``vmap`` (each option's ``carry_pending`` and
  ``update`` over its rows, mapped over the options with ``OPTION_AXES``: the update
  before ``update_options`` existed), ``each_option`` (the fallback of an agent without
  ``update_options``) and ``grouped`` (the agent's ``update_options``, ``option_update``
  "grouped", at each ``--per-step``: blocks per pass of its loop); the learners are
  donated and come back whole, as in the trainer's chunk (a DQN buffer is then written
  in place);
* ``chunk``: ``Engine.joint_chunk`` as the trainer calls it (rollouts + updates), for an
  agent without ``update_options`` and with it.

``--algo`` picks the learner (ppo, actor-critic, dqn), ``--agent KEY=JSON`` sets a field
of its config; ``--kernels`` (an accelerator) also reports each program's kernels
(``benchmarks/_kernels.py``). ``--per-step 1 16`` times the grouped update (and chunk)
at 1 and at 16 blocks per pass of its loop (``option_blocks_per_step``).

The variants alternate within every repeat, so a noisy (shared) machine hits each alike;
medians are printed, with the ratio to the first variant.

    python benchmarks/joint_update_cost.py --task craft/get_gem --env observation=compact \
        --seeds 2 --repeats 7
    python benchmarks/joint_update_cost.py --algo actor-critic --task craft/make_goldarrow \
        --env observation=compact --seeds 1 --skip-chunk
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
from _kernels import describe, kernel_profile  # noqa: E402


def build(args, agent_cfg: dict):
    import smjax
    from smjax.train.config import TrainConfig
    from smjax.train.engine import Engine
    from smjax.train.learner import make_learner
    from smjax.train.plans import resolve_hierarchy

    env, params = smjax.make(args.task, **dict(kv.split("=", 1) for kv in args.env))
    cfg = TrainConfig(algo=args.algo, num_envs=args.num_envs, rollout_ticks=args.rollout_ticks,
                      updates_per_chunk=args.updates, agent=agent_cfg)
    _, h = resolve_hierarchy(env, cfg)
    agent = make_learner(env, params, cfg)
    return Engine(env, params, h, agent, cfg), agent._replace(update_options=None)


def joint_state(engine, seeds: int):
    keys = jax.random.split(jax.random.PRNGKey(0), 4 * seeds).reshape(4, seeds, 2)
    fresh = engine.init_learner(keys[0])
    return engine.joint_state(fresh, engine.new_bank(engine.init_learner(keys[1])), keys[2],
                              keys[3])


def record_rollout(engine, state, learned):
    """Every seed's joint record of one rollout ``[S, T, B, O]``."""
    from smjax.options.runner import NO_OPTION, Controls

    O = engine.h.num_options

    def one(st, learned_s):
        controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0, jnp.int32), learned_s,
                            gamma=jnp.full((O,), 0.99, jnp.float32),
                            teleport=jnp.asarray(False), continue_episodes=jnp.asarray(False),
                            temperature=engine.temperature, side_cost=jnp.asarray(0.0),
                            acts_frozen=True, joint=True)

        def tick(c, k):
            c, tr, _ = engine.runner.tick(c, k, st.learner, None, controls)
            return c, tr

        return jax.lax.scan(tick, st.carry, jax.random.split(st.key, engine.cfg.rollout_ticks))[1]

    return jax.jit(jax.vmap(one))(state, learned)


def update_variants(engine, plain_agent, grouped_engines):
    """The joint updates (grouped: where the agent has one, named by its blocks per pass
    from ``grouped_engines``), each ``(learners [O], pending [O, B], traj, key) ->
    learners``."""
    from smjax.agents.option_batch import each_option, joint_batch
    from smjax.agents.smdp import carry_pending
    from smjax.options.joint import OPTION_AXES

    def vmapped(learners, pending, traj, key):
        def one(learner, pend, tr, k):
            tr, _ = carry_pending(pend, tr)
            return plain_agent.update(learner, tr, k)[0]

        keys = jax.random.split(key, engine.h.num_options)
        return jax.vmap(one, (0, 0, OPTION_AXES, 0))(learners, pending, traj, keys)

    def batched(update_options):
        def run(learners, pending, traj, key):
            batch, _ = joint_batch(pending, traj)
            return update_options(learners, batch, key)[0]
        return run

    variants = {"vmap": vmapped, "each_option": batched(each_option(plain_agent.update))}
    for name, eng in grouped_engines.items():
        if eng.agent.update_options is not None:
            variants[name] = batched(eng.agent.update_options)
    return variants


def timed(fn, make_args, out: dict, name: str) -> None:
    """One call of ``fn`` on fresh arguments; the first call (compile included) apart."""
    args = jax.block_until_ready(make_args())
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    seconds = time.perf_counter() - t0
    if name not in out:
        out[name] = {"first_s": seconds, "runs": []}
    else:
        out[name]["runs"].append(seconds)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--algo", default="ppo", help="ppo, actor-critic or dqn")
    ap.add_argument("--task", default="craft/get_gem")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--agent", action="append", default=[], metavar="KEY=JSON",
                    help="a learner config field, e.g. normalize_advantages=true")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--num-envs", type=int, default=128)
    ap.add_argument("--rollout-ticks", type=int, default=32)
    ap.add_argument("--updates", type=int, default=4, help="updates (rollouts) per chunk")
    ap.add_argument("--block", type=int, default=None,
                    help="option_block of PPO or the actor-critic (default: its own)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--skip-chunk", action="store_true")
    ap.add_argument("--kernels", action="store_true",
                    help="also trace each variant's kernels (an accelerator: launches, busy "
                         "time, the longest kernels)")
    ap.add_argument("--per-step", type=int, nargs="+", default=[0], metavar="K",
                    help="blocks per pass of the grouped loop to time (0: the backend's)")
    args = ap.parse_args(argv)
    agent_cfg = {k: json.loads(v) for k, v in (kv.split("=", 1) for kv in args.agent)}
    if args.block is not None:
        agent_cfg["option_block"] = args.block
    # the grouped update, whatever "auto" picks on this backend
    grouped_cfg = dict(agent_cfg, option_update="grouped")
    engine, plain = build(args, grouped_cfg)
    if args.algo == "dqn":  # no loop over blocks: nothing per pass to vary
        grouped_engines = {"grouped": engine}
    else:
        grouped_engines = {
            ("grouped" if k == 0 else f"grouped_{k}"): build(
                args, dict(grouped_cfg, option_blocks_per_step=k))[0] for k in args.per_step}
    S, O = args.seeds, engine.h.num_options
    state = joint_state(engine, S)
    learned = jnp.ones((S, O), bool)
    traj = record_rollout(engine, state, learned)
    print("decisions per option (seed 0):", traj.decision[0].sum((0, 1)).tolist(),
          f"of {args.rollout_ticks} x {args.num_envs} ticks", flush=True)
    pending = state.carry.pending
    key = jax.random.split(jax.random.PRNGKey(5), S)
    # the learners donated, as the trainer's chunk does (a DQN buffer is written in place)
    progs = {name: jax.jit(jax.vmap(fn), donate_argnums=0)
             for name, fn in update_variants(engine, plain, grouped_engines).items()}
    chunks = {}
    if not args.skip_chunk:
        from smjax.train.engine import Engine
        from smjax.train.state import SuccessWindow

        old = Engine(engine.env, engine.env_params, engine.h, plain, engine.cfg)
        windows = (SuccessWindow.empty(S, 256), SuccessWindow.empty(S, 256))
        rest = (jnp.ones((S,), bool), learned, jnp.zeros((S,), jnp.float32),
                jnp.full((S, O), 0.99, jnp.float32), windows,
                jnp.tile(jnp.asarray([256, 256], jnp.int32), (S, 1)))
        chunks = {"chunk_each_option": (old, rest)}
        chunks.update({f"chunk_{name}": (eng, rest) for name, eng in grouped_engines.items()})
    out: dict = {}
    for _ in range(args.repeats + 1):  # the first round compiles
        for name, prog in progs.items():
            timed(prog, lambda: (jax.tree.map(jnp.copy, state.learner), pending, traj, key),
                  out, name)
        for name, (eng, rest) in chunks.items():  # (the chunk consumes its state: a copy)
            timed(lambda st, *r, e=eng: e.joint_chunk(st, *r)[1],
                  lambda: (jax.tree.map(jnp.copy, state),) + rest, out, name)
    report(out, args)
    if args.kernels:
        for name, prog in progs.items():
            print(f"{name} kernels:", flush=True)
            print(describe(kernel_profile(lambda p=prog: p(
                jax.tree.map(jnp.copy, state.learner), pending, traj, key))), flush=True)
        for name, (eng, rest) in chunks.items():
            print(f"{name} kernels:", flush=True)
            print(describe(kernel_profile(lambda e=eng, r=rest: e.joint_chunk(
                jax.tree.map(jnp.copy, state), *r)[1])), flush=True)


def report(out: dict, args) -> None:
    base = {}
    for name, rec in out.items():
        med = statistics.median(rec["runs"])
        group = name.split("_")[0] if name.startswith("chunk") else "update"
        base.setdefault(group, (name, med))
        ref, ref_med = base[group]
        print(f"{name:18s} median {med:8.3f} s of {len(rec['runs'])} (first call with compile "
              f"{rec['first_s']:.1f} s); {med / ref_med:.2f}x of {ref}, "
              f"{ref_med / med:.2f}x faster", flush=True)
    print(f"{args.algo} {args.agent} task {args.task} {args.env} seeds {args.seeds} envs {args.num_envs} ticks "
          f"{args.rollout_ticks} updates/chunk {args.updates} on "
          f"{jax.devices()[0].platform}", flush=True)


if __name__ == "__main__":
    main()
