"""Where a training chunk's time goes, and its FLOPs per env step.

Builds the training ``Engine`` for a task (any environment, hierarchy, learner) with the
trainer's own shapes (seeds x envs x ticks x updates) at a chosen level, and times, each
as its own compiled program over the same shapes, the parts seed-vmapped (median of
``--repeats`` runs, compile timed apart):

* ``chunk``: ``Engine.chunk`` as the trainer calls it (rollouts + updates; its seeds side by
  side or one after another, as on this backend, or as ``--seed-by-seed`` says);
* ``rollout``: the chunk's rollouts alone (hierarchical ticks, no update);
* ``update``: the learner's updates alone (on a rollout's trajectory);
* ``env_step``: the environment's ``step_env`` alone, same number of steps;
* ``reset``: ``reset_env`` for every environment and tick (what auto-reset costs where
  the tick generates a fresh episode for every environment);
* ``policy_bank``: the frozen policies' logits for every option, environment and tick;
* ``learner_act``: the learner's own action sampling;
* ``teleports``: every teleport family applied to every environment;
* ``gate``: one acceptance-gate attempt of the level (``gate_envs`` episodes).

With ``--kernels`` (an accelerator) each part also reports, from a profiler trace, the
kernels one call launches, the time the device was busy with them and the longest ones
(``benchmarks/_kernels.py``).

The isolated parts overlap (the rollout contains the env step, reset, bank and act) and
do not add up to the chunk exactly: XLA fuses them differently when they run together.
FLOPs are counted from the networks' layer shapes (dense layers only: 2 x in x out per
sample and layer; a backward pass is counted as twice the forward).

    python benchmarks/profile_training.py --task craft/get_gem --env observation=compact \
        --seeds 10 --num-envs 128 --level 1
"""
from __future__ import annotations

import argparse
import inspect
import json
import os
import statistics
import sys
import time

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _kernels import (  # noqa: E402
    describe, fused_computations, kernel_profile, kernels_by_source,
)


def _median_time(fn, args, repeats: int, kernels: bool = False, fusions: bool = False
                 ) -> tuple[float, float, dict | None, tuple | None]:
    """(compile seconds, median run seconds, kernel profile or None, (fused computations of
    the optimized HLO, its launches by source line) or None) of ``jax.jit(fn)(*args)``."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    hlo = compiled.as_text() if fusions else ""
    fused = (fused_computations(hlo), kernels_by_source(hlo)) if fusions else None
    jax.block_until_ready(compiled(*args))
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        runs.append(time.perf_counter() - t0)
    profile = kernel_profile(lambda: compiled(*args)) if kernels else None
    return compile_s, statistics.median(runs), profile, fused


def dense_flops(params) -> int:
    """Multiply-add FLOPs of one forward pass for one sample (2 x in x out per kernel)."""
    total = 0
    for path, leaf in jax.tree_util.tree_leaves_with_path(params):
        if getattr(path[-1], "key", None) == "kernel" and leaf.ndim >= 2:
            total += 2 * leaf.shape[-2] * leaf.shape[-1]
    return total


def build(args):
    import smjax
    from smjax.train.config import TrainConfig
    from smjax.train.engine import Engine, SeedState
    from smjax.train.learner import make_learner
    from smjax.train.plans import plan_levels, resolve_hierarchy

    overrides = dict(kv.split("=", 1) for kv in args.env)
    env, params = smjax.make(args.task, **overrides)
    cfg = TrainConfig(method=args.method, algo=args.algo, num_envs=args.num_envs,
                      rollout_ticks=args.rollout_ticks, updates_per_chunk=args.updates)
    _, h = resolve_hierarchy(env, cfg)
    plans = plan_levels(h, cfg.method)
    plan = plans[args.level - 1]
    engine = Engine(env, params, h, make_learner(env, params, cfg), cfg)
    S = args.seeds
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(S, dtype=jnp.uint32))
    split = jax.vmap(lambda k: jax.random.split(k, 3))(keys)
    learner = engine.init_learner(split[:, 0])
    start = jnp.full((S,), plan.start, jnp.int32)
    state = SeedState(engine.reset(split[:, 1], start), learner, split[:, 2])
    bank = engine.new_bank(learner)
    learned = jnp.zeros((S, h.num_options), bool)
    for earlier in plans[: args.level - 1]:
        learned = learned.at[:, earlier.option].set(True)
    return env, params, h, cfg, engine, plan, state, bank, learned, keys


def profile(args) -> dict:
    from smjax.options.runner import Controls
    from smjax.train.engine import SeedState

    env, params, h, cfg, engine, plan, state, bank, learned, keys = build(args)
    runner, agent = engine.runner, engine.agent
    S, B, T, U = args.seeds, cfg.num_envs, cfg.rollout_ticks, cfg.updates_per_chunk
    steps = S * B * T * U
    learner_id, start = jnp.asarray(plan.option), jnp.asarray(plan.start)
    learners, starts = jnp.full((S,), plan.option, jnp.int32), jnp.full((S,), plan.start, jnp.int32)
    active = jnp.ones((S,), bool)
    out: dict = {"task": args.task, "env": args.env, "algo": cfg.algo, "level": args.level,
                 "option": plan.name, "seeds": S, "num_envs": B, "rollout_ticks": T,
                 "updates_per_chunk": U, "env_steps_per_chunk": steps,
                 "device": jax.devices()[0].platform, "parts": {}}

    def record(name, fn, fn_args, n=steps):
        if args.parts and name not in args.parts:
            return
        compile_s, run_s, kernels, fused = _median_time(fn, fn_args, args.repeats, args.kernels,
                                                        args.fusions)
        out["parts"][name] = {"seconds": run_s, "compile_seconds": compile_s,
                              "env_steps_per_second": n / run_s}
        fused_text = "" if fused is None else f"  {fused[0]:5d} fusions"
        print(f"{name:12s} {run_s:8.3f} s  compile {compile_s:6.1f} s  "
              f"{n / run_s:12,.0f} env steps/s{fused_text}", flush=True)
        if fused is not None:
            out["parts"][name].update(fusions=fused[0], launches_by_source=dict(fused[1]))
            print(f"   {sum(fused[1].values())} launches in the program's text; most from:")
            for where, count in fused[1].most_common(args.sources):
                print(f"     {count:4d}  {where}", flush=True)
        if kernels is not None:
            out["parts"][name]["kernels"] = kernels
            print(describe(kernels), flush=True)

    # the whole chunk, its seeds arranged as the trainer arranges them (trees without
    # ``Engine.seed_by_seed``: side by side) unless --seed-by-seed says; no donation here,
    # so it can repeat
    one_after_another = {"on": True, "off": False}.get(
        args.seed_by_seed, getattr(engine, "seed_by_seed", False))
    chunk = jax.vmap(engine.seed_chunk) if not one_after_another else (
        lambda *xs: jax.lax.map(lambda per_seed: engine.seed_chunk(*per_seed), xs))
    # a level's per-seed switches, those this tree's chunk takes (older trees take fewer)
    level = {"teleport": jnp.ones((S,), bool), "continue_episodes": jnp.zeros((S,), bool),
             "side_cost": jnp.zeros((S,), jnp.float32),
             "gamma": jnp.full((S,), cfg.gamma, jnp.float32)}
    takes = inspect.signature(engine.seed_chunk).parameters
    if "windows" in takes:  # the running-success windows the trainer pushes every update
        from smjax.train.state import SuccessWindow

        pair = SuccessWindow.pair(S, cfg.window_slots)
        level["windows"] = (pair["window"], pair["task_window"])
        level["sizes"] = jnp.tile(jnp.asarray([cfg.success_window, 0], jnp.int32), (S, 1))
    if "tick" in takes:  # the per-seed settings as one ChunkControls
        from smjax.train.engine import ChunkControls

        tick = ChunkControls(learners, starts, level["teleport"], level["continue_episodes"],
                             level["side_cost"], level["gamma"])
        rest = tuple(v for k, v in level.items() if k in ("windows", "sizes"))
        call = lambda st: chunk(st, active, bank, learned, tick, *rest)[1]  # noqa: E731
    else:
        switches = tuple(v for k, v in level.items() if k in takes)
        call = lambda st: chunk(st, active, bank, learned, learners, starts, *switches)[1]  # noqa: E731
    record("chunk", call, (state,))
    # the level's tick settings, as the chunk's (an older tree's runner held the
    # temperature: None there)
    settings = dict(gamma=float(cfg.gamma), temperature=getattr(engine, "temperature", None))

    def rollout_one(st: SeedState, bank_s, learned_s):
        controls = Controls(learner_id, start, learned_s, **settings)

        def tick_fn(c, k):
            c, tr, _ = runner.tick(c, k, st.learner, bank_s, controls)
            return c, tr

        def one(c, k):
            if hasattr(runner, "refill"):  # the reset pool, refilled before every rollout
                c = runner.refill(c, jax.random.fold_in(k, 1))
            return jax.lax.scan(tick_fn, c, jax.random.split(k, T))

        carry, traj = jax.lax.scan(one, st.carry, jax.random.split(st.key, U))
        return traj

    rollout = jax.vmap(rollout_one)
    record("rollout", lambda st: rollout(st, bank, learned).reward.sum(), (state,))
    traj = jax.jit(rollout)(state, bank, learned)
    traj0 = jax.tree.map(lambda x: x[:, 0], traj)  # one rollout per seed [S, T, B, ...]

    def updates(st: SeedState, tr):
        def body(ls, k):
            ls, _ = agent.update(ls, tr, k)
            return ls, None

        ls, _ = jax.lax.scan(body, st.learner, jax.random.split(st.key, U))
        return ls

    record("update", jax.vmap(updates), (state, traj0))

    env_state = state.carry.env_state
    actions = jnp.zeros((S, B), jnp.int32)

    def env_steps(es, acts, key):
        def body(s, k):
            ks = jax.random.split(k, B)
            _, s, r, *_ = jax.vmap(env.step_env, (0, 0, 0, None))(ks, s, acts, params)
            return s, r.sum()

        return jax.lax.scan(body, es, jax.random.split(key, T * U))[1].sum()

    record("env_step", jax.vmap(env_steps), (env_state, actions, keys))

    def resets(key):
        def body(c, k):
            obs, s = jax.vmap(env.reset_env, (0, None))(jax.random.split(k, B), params)
            return c + jnp.asarray(obs, jnp.float32).sum(), None

        return jax.lax.scan(body, 0.0, jax.random.split(key, T * U))[0]

    record("reset", jax.vmap(resets), (keys,))

    obs = state.carry.obs

    def bank_logits(bank_s, obs_s, learned_s):
        def body(c, _):
            if hasattr(runner, "frozen_logits"):  # only the options that can decide
                lg = runner.frozen_logits(bank_s, obs_s + c * 0,
                                          Controls(learner_id, start, learned_s, **settings))
            else:
                lg = jax.vmap(agent.policy_logits, (0, None))(bank_s, obs_s + c * 0)
            return c + lg.sum() * 1e-9, None

        return jax.lax.scan(body, 0.0, None, T * U)[0]

    record("policy_bank", jax.vmap(bank_logits), (bank, obs, learned))

    mask = jnp.ones((S, B, h.num_actions), bool)

    def acts(ls, obs_s, mask_s, key):
        def body(c, k):
            a = agent.act(ls, obs_s, mask_s, k)
            return c + a.log_prob.sum(), None

        return jax.lax.scan(body, 0.0, jax.random.split(key, T * U))[0]

    record("learner_act", jax.vmap(acts), (state.learner, obs, mask, keys))

    if runner.teleport_families:
        chosen = jnp.ones((S, B), jnp.int32)  # every environment calls option 1's teleport

        def teleports(es, ch, key):
            def body(c, k):
                s, a = runner.run_family(runner.teleport_families, k, es, ch,
                                          jnp.zeros((B,), runner.action_dtype), controls=False)
                return c + a.sum(), None

            return jax.lax.scan(body, 0, jax.random.split(key, T * U))[0]

        record("teleports", jax.vmap(teleports), (env_state, chosen, keys))

    if not args.parts or "gate" in args.parts:
        gate_s, gate_compile, gate_steps = time_gate(engine, keys, state, bank, learned, learner_id,
                                                     start, active)
        out["parts"]["gate"] = {"seconds": gate_s, "compile_seconds": gate_compile,
                                "env_steps": gate_steps,
                                "env_steps_per_second": gate_steps / gate_s}
        print(f"{'gate':12s} {gate_s:8.3f} s  compile {gate_compile:6.1f} s  "
              f"{gate_steps / gate_s:12,.0f} env steps/s ({gate_steps:,} steps)", flush=True)

    learner_params = jax.tree.map(lambda x: x[0], state.learner.params)
    per_fwd = dense_flops(learner_params)
    bank_fwd = dense_flops(jax.tree.map(lambda x: x[0, 0], bank))
    out["flops"] = flops_per_step(cfg, agent.name, per_fwd, bank_fwd, h.num_options)
    print("FLOPs per env step:", json.dumps(out["flops"]), flush=True)
    return out


def time_gate(engine, keys, state, bank, learned, learner_id, start, active):
    """(seconds, compile seconds, env steps) of one gate attempt for every seed."""
    if isinstance(getattr(engine, "gate", None), jax.stages.Wrapped):  # before 2026-11-23
        args = (keys, state, bank, learned, learner_id, start, jnp.asarray(0, jnp.uint32), active)
        t0 = time.perf_counter()
        compiled = engine.gate.lower(*args).compile()
        compile_s = time.perf_counter() - t0
        call = lambda: compiled(*args)  # noqa: E731
    else:
        S = keys.shape[0]
        gate_args = (keys, state, bank, learned, [int(learner_id)] * S, [int(start)] * S,
                     [True] * S, [engine.cfg.threshold] * S)
        compile_s = engine.gate(*gate_args)[1]
        call = lambda: engine.gate(*gate_args)[0]  # noqa: E731
    jax.block_until_ready(call())
    t0 = time.perf_counter()
    res = jax.block_until_ready(call())
    return time.perf_counter() - t0, compile_s, int(jnp.sum(res["env_steps"]))


def flops_per_step(cfg, algo: str, learner_fwd: int, bank_fwd: int, num_options: int) -> dict:
    """Dense-layer FLOPs per env step: acting, frozen policies, and the update (whose
    backward counts twice its forward)."""
    agent_cfg = cfg.agent
    if algo in ("ppo",):
        epochs = agent_cfg.get("update_epochs", 4)
        update = 3 * learner_fwd * epochs
    elif algo == "actor-critic":
        update = 3 * learner_fwd
    else:  # dqn: replay updates are not per env step; left out
        update = 0
    return {"act": learner_fwd, "policy_bank": bank_fwd * num_options, "update": update,
            "total": learner_fwd + bank_fwd * num_options + update}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="craft/get_gem")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE",
                    help="environment override, repeatable (e.g. observation=compact)")
    ap.add_argument("--method", default="top-down")
    ap.add_argument("--algo", default="ppo")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--num-envs", type=int, default=128)
    ap.add_argument("--rollout-ticks", type=int, default=32)
    ap.add_argument("--updates", type=int, default=4, help="updates (rollouts) per chunk")
    ap.add_argument("--level", type=int, default=1, help="which planned level (1 = first)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--parts", nargs="+", default=[], metavar="PART",
                    help="time only these parts (chunk, rollout, update, ..., gate; "
                         "default: all); each part compiles its own program")
    ap.add_argument("--seed-by-seed", choices=("auto", "on", "off"), default="auto",
                    help="the chunk's seeds one after another (on: lax.map) or side by side "
                         "(off: vmap); auto: as the trainer runs them on this backend")
    ap.add_argument("--kernels", action="store_true",
                    help="also trace each part's kernels (an accelerator: launches, busy "
                         "time, the longest kernels)")
    ap.add_argument("--fusions", action="store_true",
                    help="also count each part's fused computations (XLA's kernels, what its "
                         "compile time follows) and where its launches come from (source "
                         "lines; each once, however often its loop runs)")
    ap.add_argument("--sources", type=int, default=8, metavar="N",
                    help="with --fusions, how many source lines to print (default 8)")
    ap.add_argument("--json", help="also write the result here")
    args = ap.parse_args(argv)
    out = profile(args)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
