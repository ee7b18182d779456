"""Where smjax's flat PPO spends its time relative to rejax's: rollout vs update.

Ablations of the end-to-end jitted training programs, same form for both learners, on
one gymnax environment and the ``ppo_vs_rejax.py`` hyper-parameters:

* full training (``num_updates`` x (rollout + update));
* rollout only: the same program with the learner update removed (smjax: an agent
  whose ``update`` returns its state unchanged; rejax: ``collect_trajectories`` alone);
* smjax with the update's minibatch assignment swapped for a plain permutation (as
  rejax does), which isolates the cost of dealing decisions evenly (an ``argsort``).

The update's cost is full - rollout only::

    python benchmarks/peers/profile_flat_ppo.py --env CartPole-v1 --num-envs 16 --num-steps 128 \
        --total-steps 65536
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
from ppo_vs_rejax import parse_args as ppo_args  # noqa: E402
from ppo_vs_rejax import rejax_trainer, smjax_trainer  # noqa: E402


def permutation_indices(key, decision, num_minibatches):
    """rejax-style minibatches: one random permutation split in equal parts (no dealing)."""
    num_items = decision.shape[0]
    size = -(-num_items // num_minibatches)
    pad = num_minibatches * size - num_items
    order = jax.random.permutation(key, num_items)
    idx = jnp.concatenate([order, jnp.zeros((pad,), order.dtype)])
    real = jnp.concatenate([jnp.ones((num_items,), bool), jnp.zeros((pad,), bool)])
    return idx.reshape(num_minibatches, size), real.reshape(num_minibatches, size)


def smjax_variant(cfg, genv, gparams, variant: str):
    from smjax.agents import make_agent as real_make_agent
    from smjax.agents import ppo

    import smjax.agents as agents_pkg

    saved_make, saved_idx = agents_pkg.make_agent, ppo.minibatch_indices
    try:
        if variant == "rollout only":
            def no_update_agent(algo, **kw):
                agent = real_make_agent(algo, **kw)
                return agent._replace(update=lambda state, traj, last_obs, key: (state, {}))
            agents_pkg.make_agent = no_update_agent
        elif variant == "permutation minibatches":
            ppo.minibatch_indices = permutation_indices
        run, _, steps = smjax_trainer(cfg, genv, gparams)
        # make_train traces lazily: trace now, while the patch is in place.
        lowered = jax.jit(run).lower(jax.random.PRNGKey(cfg.seed))
    finally:
        agents_pkg.make_agent, ppo.minibatch_indices = saved_make, saved_idx
    return lowered, steps


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="CartPole-v1")
    p.add_argument("--profile-json", default=os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                          "profile_flat_ppo.json"))
    args, rest = p.parse_known_args(argv)
    cfg = ppo_args(rest + ["--envs", args.env])

    import gymnax

    genv, gparams = gymnax.make(args.env)
    key = jax.random.PRNGKey(cfg.seed)
    programs = {}
    for variant in ("full", "rollout only", "permutation minibatches"):
        programs[f"smjax {variant}"] = smjax_variant(cfg, genv, gparams, variant)

    run, _, steps = rejax_trainer(cfg, genv, gparams)
    programs["rejax full"] = (jax.jit(run).lower(key), steps)
    algo = run.algo

    def rejax_rollout_only(key):
        ts = jax.lax.fori_loop(0, steps // (cfg.num_envs * cfg.num_steps),
                               lambda _, ts: algo.collect_trajectories(ts)[0], algo.init_state(key))
        return ts.last_obs.sum() + ts.global_step

    programs["rejax rollout only"] = (jax.jit(rejax_rollout_only).lower(key), steps)

    rows, out = [], {}
    compiled, compile_s = {}, {}
    for name, (lowered, _) in programs.items():
        t0 = time.perf_counter()
        compiled[name] = lowered.compile()
        compile_s[name] = time.perf_counter() - t0
        jax.block_until_ready(compiled[name](key))  # warm-up, untimed
    runs = {name: [] for name in programs}
    for _ in range(cfg.repeats):  # interleaved, so load drift hits every program alike
        for name in programs:
            t0 = time.perf_counter()
            jax.block_until_ready(compiled[name](key))
            runs[name].append(time.perf_counter() - t0)
    for name, (_, steps) in programs.items():
        med = statistics.median(runs[name])
        out[name] = {"median_s": med, "run_s": runs[name], "compile_s": compile_s[name],
                     "env_steps_per_s": steps / med}
        rows.append([name, med, steps / med, compile_s[name]])
    for who in ("smjax", "rejax"):
        out[f"{who} update (full - rollout)"] = {
            "median_s": out[f"{who} full"]["median_s"] - out[f"{who} rollout only"]["median_s"]}
        rows.append([f"{who} update (full - rollout)", out[f"{who} update (full - rollout)"]["median_s"], "", ""])
    _common.print_table(["program", "median s", "env steps/s", "compile s"], rows)
    summary = {"benchmark": "profile_flat_ppo", "env": args.env,
               "config": {k: v for k, v in vars(cfg).items() if k != "json"},
               "machine": _common.machine(), "versions": _common.versions("gymnax", "rejax", "smjax"),
               "results": out}
    _common.write_json(args.profile_json, summary)
    print(json.dumps({"benchmark": "profile_flat_ppo", "env": args.env,
                      "loadavg": summary["machine"]["loadavg_1_5_15"],
                      "median_s": {k: round(v["median_s"], 4) for k, v in out.items()}}))
    return summary


if __name__ == "__main__":
    main()
