"""smjax Craft's step vs Craftax-Classic's step (symbolic observations, same batch sizes).

Each measurement is one jitted ``lax.scan`` of ``--steps`` auto-resetting steps over
``num_envs`` already-reset environments with uniformly random actions drawn inside the scan; the
observation rides in the carry so every step materialises it (as a rollout buffer or a
network input would). Compile is timed separately; the median of ``--repeats`` runs is
reported::

    python benchmarks/peers/craft_vs_craftax.py --num-envs 64 1024 4096 --steps 64

Work per step differs a lot: smjax's ``craft/get_gem`` is the paper's small Craft world
(a 12x12 grid, 5 primitive actions, no creatures, no day/night, no health or
food), while Craftax-Classic simulates a 64x64 world with zombies, skeletons, cows and
arrows, daylight, health/food/drink/energy, 17 actions and 22 achievements, and its
gymnax-style auto-reset generates a whole new 64x64 world (noise maps) inside every
step and selects it only where an episode ended.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

CRAFTAX_NAMES = ("Craftax-Classic-Symbolic-v1", "Craftax-Classic-Symbolic-AutoReset-v1")


def make_smjax(obs_kind: str):
    from smjax.envs.craft.env import make_craft

    env, params = make_craft("get_gem", observation=obs_kind)
    step = lambda key, state, action: env.step(key, state, action, params)[:3]  # noqa: E731
    reset = lambda key: env.reset(key, params)  # noqa: E731
    return reset, step, env.action_space(params).n, env.observation_space(params).shape


def make_craftax(auto_reset: bool = True):
    """Craftax-Classic symbolic; ``auto_reset=False`` is its step without the per-step world reset."""
    from craftax.craftax_env import make_craftax_env_from_name

    env = None
    for name in CRAFTAX_NAMES:
        try:
            env = make_craftax_env_from_name(name, auto_reset=auto_reset)
            break
        except (ValueError, KeyError):
            continue
    if env is None:
        raise ValueError(f"this craftax version knows none of {CRAFTAX_NAMES}")
    params = env.default_params
    step = lambda key, state, action: env.step(key, state, action, params)[:3]  # noqa: E731
    reset = lambda key: env.reset(key, params)  # noqa: E731
    return reset, step, env.action_space(params).n, env.observation_space(params).shape


def make_runner(reset, step, num_actions: int, num_envs: int, steps: int):
    """``(run(key, obs, state), initial (obs, state))``: the reset happens outside the timed
    program, so short scans (Craftax on CPU) are not dominated by world generation."""
    vstep = jax.vmap(step)
    initial = jax.jit(jax.vmap(reset))(jax.random.split(jax.random.PRNGKey(12345), num_envs))

    def run(key, obs, state):
        def body(carry, _):
            state, key, acc, _ = carry
            key, key_act, key_step = jax.random.split(key, 3)
            actions = jax.random.randint(key_act, (num_envs,), 0, num_actions)
            obs, state, reward = vstep(jax.random.split(key_step, num_envs), state, actions)
            return (state, key, acc + reward.astype(jnp.float32).sum(), obs), None

        (_, _, acc, obs), _ = jax.lax.scan(body, (state, key, jnp.float32(0), obs), None, steps)
        return acc + jnp.sum(obs, dtype=jnp.float32)

    return run, initial


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--num-envs", type=int, nargs="+", default=[64, 1024, 4096])
    p.add_argument("--steps", type=int, default=64, help="steps per timed scan")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--smjax-obs", nargs="+", default=["paper", "compact"], choices=["paper", "compact", "none"])
    p.add_argument("--craftax-no-reset", action="store_true",
                   help="also time Craftax-Classic without auto-reset (its step_env alone; episodes "
                        "then run on past their end, which only matters for timing)")
    p.add_argument("--craftax-steps", type=int, default=None,
                   help="steps per timed scan for Craftax (default: --steps); Craftax is slow on CPU")
    p.add_argument("--craftax-auto-reset-max-envs", type=int, default=None,
                   help="skip auto-resetting Craftax above this batch size (on CPU it slows "
                        "superlinearly: 45 steps/s at 1024 envs)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "craft_vs_craftax.json"))
    args = p.parse_args(argv)

    variants = {f"smjax craft/get_gem ({kind})": make_smjax(kind) for kind in args.smjax_obs}
    variants["Craftax-Classic symbolic"] = make_craftax()
    if args.craftax_no_reset:
        variants["Craftax-Classic symbolic, no auto-reset"] = make_craftax(auto_reset=False)
    key = jax.random.PRNGKey(args.seed)
    results = []
    for num_envs in args.num_envs:
        row = {"num_envs": num_envs}
        for name, (reset, step, num_actions, obs_shape) in variants.items():
            if (name == "Craftax-Classic symbolic" and args.craftax_auto_reset_max_envs is not None
                    and num_envs > args.craftax_auto_reset_max_envs):
                row[name] = None
                print(f"[{num_envs}] {name}: skipped (--craftax-auto-reset-max-envs)", flush=True)
                continue
            steps = args.steps if name.startswith("smjax") or args.craftax_steps is None else args.craftax_steps
            run, (obs0, state0) = make_runner(reset, step, num_actions, num_envs, steps)
            timing = _common.compile_and_time(run, (key, obs0, state0), args.repeats)
            timing.pop("output")
            row[name] = dict(timing, steps_per_s=num_envs * steps / timing["median_s"], steps=steps,
                             obs_shape=list(obs_shape), num_actions=num_actions)
            print(f"[{num_envs}] {name}: {row[name]['steps_per_s']:,.0f} steps/s "
                  f"(compile {timing['compile_s']:.1f}s)", flush=True)
        ours = [n for n in variants if n.startswith("smjax")]
        theirs = [n for n in variants if not n.startswith("smjax")]
        row["ratios"] = {f"{o} / {t}": (row[o]["steps_per_s"] / row[t]["steps_per_s"] if row[t] else None)
                         for o in ours for t in theirs}
        results.append(row)
    names = list(variants)
    sps = lambda r, n: r[n]["steps_per_s"] if r[n] else "skipped"  # noqa: E731
    ratio_names = list(results[0]["ratios"])
    _common.print_table(
        ["num_envs"] + [f"{n} steps/s" for n in names] + [f"ratio {k}" for k in ratio_names],
        [[r["num_envs"]] + [sps(r, n) for n in names]
         + [r["ratios"][k] if r["ratios"][k] is not None else "-" for k in ratio_names] for r in results])
    summary = {"benchmark": "craft_vs_craftax", "config": {k: v for k, v in vars(args).items() if k != "json"},
               "machine": _common.machine(), "versions": _common.versions("craftax", "smjax"), "results": results}
    _common.write_json(args.json, summary)
    print(json.dumps({"benchmark": "craft_vs_craftax", "loadavg": summary["machine"]["loadavg_1_5_15"],
                      "results": {str(r["num_envs"]): {**{n: round(r[n]["steps_per_s"]) if r[n] else None
                                                          for n in names},
                                                       "ratios": {k: (round(v, 2) if v else None)
                                                                  for k, v in r["ratios"].items()}}
                                  for r in results}}))
    return summary


if __name__ == "__main__":
    main()
