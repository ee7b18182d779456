"""smjax's PPO vs rejax's PPO on the same gymnax environments, same hyper-parameters.

Both learners train end to end as one jitted program for the same number of
environment steps; the script reports training env steps/s (median of ``--repeats``
runs, compile timed separately), the final policy's mean return (both evaluated by the
same evaluator here: ``--eval-episodes`` fresh episodes, actions sampled from the
policy), and the throughput ratio smjax/rejax::

    python benchmarks/peers/ppo_vs_rejax.py --envs CartPole-v1,Breakout-MinAtar \
        --num-envs 16 --num-steps 128 --total-steps 131072

Matched: num_envs, num_steps, epochs, minibatches, learning rate, gamma, GAE lambda,
clip epsilon (policy and value), entropy and value coefficients, hidden sizes and
activation, separate actor/critic MLPs, Adam eps (set to rejax's 1e-8), total steps.
Not matchable through the two configs: rejax clips each gradient element to
``max_grad_norm`` (``optax.clip``) and keeps one optimiser per network, smjax clips the
global norm of one optimiser; rejax normalises advantages per minibatch, smjax over the
whole rollout; smjax's PPO masks per-tick decisions (all ticks decide in flat training).
rejax's periodic evaluation is replaced by a no-op so that only training is timed.
"""
from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", default="CartPole-v1,Breakout-MinAtar", help="comma-separated gymnax ids")
    p.add_argument("--num-envs", type=int, default=16)
    p.add_argument("--num-steps", type=int, default=128, help="rollout length per update")
    p.add_argument("--total-steps", type=int, default=131072, help="training env steps per run")
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--minibatches", type=int, default=4)
    p.add_argument("--lr", type=float, default=2.5e-3)
    p.add_argument("--hidden", default="64,64")
    p.add_argument("--activation", default="tanh")
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--eval-episodes", type=int, default=64)
    p.add_argument("--eval-max-steps", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "ppo_vs_rejax.json"))
    args = p.parse_args(argv)
    args.hidden = tuple(int(h) for h in args.hidden.split(","))
    batch = args.num_envs * args.num_steps
    if args.total_steps < batch or batch % args.minibatches:
        p.error(f"--total-steps must be >= num_envs*num_steps ({batch}) and num_envs*num_steps "
                f"divisible by --minibatches ({args.minibatches})")
    return args


def smjax_trainer(args, gymnax_env, gymnax_params):
    """``train(key) -> logits_fn``-ready params of smjax's PPO via the gymnax adapter."""
    from smjax.agents import make_agent
    from smjax.agents.flat_train import FlatTrainConfig, make_train
    from smjax.core.adapters import from_gymnax

    env, params = from_gymnax(gymnax_env, gymnax_params)
    agent = make_agent(
        "ppo", learning_rate=args.lr, update_epochs=args.epochs, num_minibatches=args.minibatches,
        hidden_sizes=args.hidden, activation=args.activation, max_grad_norm=args.max_grad_norm,
        adam_eps=1e-8, gamma=0.99, gae_lambda=0.95, clip_eps=0.2, ent_coef=0.01, vf_coef=0.5)
    num_updates = args.total_steps // (args.num_envs * args.num_steps)
    config = FlatTrainConfig(num_envs=args.num_envs, num_steps=args.num_steps, num_updates=num_updates)
    train = make_train(config, env, params, agent)

    def run(key):
        state, metrics = train(key)
        # The episode count keeps the rollouts live even when the update is ablated away.
        return state.params, metrics["episodes"].sum()

    return run, lambda p, obs: agent.policy_logits(p[0], obs), num_updates * args.num_envs * args.num_steps


def rejax_trainer(args, gymnax_env, gymnax_params):
    from rejax import PPO

    algo = PPO.create(
        env=gymnax_env, env_params=gymnax_params, num_envs=args.num_envs, num_steps=args.num_steps,
        num_epochs=args.epochs, num_minibatches=args.minibatches, learning_rate=args.lr,
        max_grad_norm=args.max_grad_norm, total_timesteps=args.total_steps,
        eval_freq=args.total_steps, skip_initial_evaluation=True, gamma=0.99, gae_lambda=0.95,
        clip_eps=0.2, ent_coef=0.01, vf_coef=0.5,
        agent_kwargs={"activation": args.activation, "hidden_layer_sizes": args.hidden})
    # Only training is timed: evaluation happens below, identically for both learners.
    algo = algo.replace(eval_callback=lambda algo, ts, rng: jnp.zeros(()))

    def run(key):
        ts, _ = algo.train(key)
        return ts.actor_ts.params

    run.algo = algo  # for profile_flat_ppo.py's ablations

    def logits(params, obs):
        return algo.actor.apply(params, obs, method="_action_dist").logits

    iteration = args.num_envs * args.num_steps
    steps = int(-(-args.total_steps // iteration)) * iteration  # rejax rounds iterations up
    return run, logits, steps


def make_evaluator(args, gymnax_env, gymnax_params):
    """Mean undiscounted return of fresh episodes with actions sampled from ``logits``."""
    from smjax.core.adapters import from_gymnax

    env, params = from_gymnax(gymnax_env, gymnax_params)
    horizon = min(args.eval_max_steps, int(getattr(params, "max_steps_in_episode", args.eval_max_steps)))

    def evaluate(logits_fn, policy_params, key):
        key_reset, key_run = jax.random.split(key)
        obs, state = jax.vmap(env.reset_env, in_axes=(0, None))(
            jax.random.split(key_reset, args.eval_episodes), params)

        def tick(carry, step_key):
            obs, state, alive, total = carry
            key_act, key_env = jax.random.split(step_key)
            action = jax.random.categorical(key_act, logits_fn(policy_params, obs))
            obs, state, reward, term, trunc, _ = jax.vmap(env.step_env, in_axes=(0, 0, 0, None))(
                jax.random.split(key_env, args.eval_episodes), state, action, params)
            total = total + jnp.where(alive, reward, 0.0)
            return (obs, state, alive & ~(term | trunc), total), None

        init = (obs, state, jnp.ones(args.eval_episodes, bool), jnp.zeros(args.eval_episodes))
        (_, _, _, total), _ = jax.lax.scan(tick, init, jax.random.split(key_run, horizon))
        return total.mean()

    return jax.jit(evaluate, static_argnums=0)


def main(argv=None) -> dict:
    import gymnax

    args = parse_args(argv)
    key = jax.random.PRNGKey(args.seed)
    results = []
    for env_id in args.envs.split(","):
        if env_id not in gymnax.registered_envs:
            raise KeyError(f"unknown gymnax id {env_id!r}; valid ids: {', '.join(gymnax.registered_envs)}")
        gymnax_env, gymnax_params = gymnax.make(env_id)
        evaluate = make_evaluator(args, gymnax_env, gymnax_params)
        row = {"env": env_id}
        made = {name: maker(args, gymnax_env, gymnax_params)
                for name, maker in (("smjax", smjax_trainer), ("rejax", rejax_trainer))}
        # Timed runs alternate between the learners so that load changes on a shared
        # machine hit both alike.
        timings = _common.compile_and_time_interleaved(
            {name: (run, (key,)) for name, (run, _, _) in made.items()}, args.repeats)
        for name, (_, logits_fn, steps) in made.items():
            timing = timings[name]
            ret = float(evaluate(logits_fn, timing.pop("output"), jax.random.PRNGKey(args.seed + 1)))
            row[name] = dict(timing, env_steps=steps, steps_per_s=steps / timing["median_s"], final_return=ret)
            print(f"[{env_id}] {name}: compile {timing['compile_s']:.1f}s, runs {timing['run_s']}, "
                  f"return {ret:.1f}", flush=True)
        row["ratio_smjax_over_rejax"] = row["smjax"]["steps_per_s"] / row["rejax"]["steps_per_s"]
        results.append(row)
    _common.print_table(
        ["env", "smjax steps/s", "rejax steps/s", "ratio smjax/rejax", "smjax return", "rejax return",
         "smjax compile s", "rejax compile s"],
        [[r["env"], r["smjax"]["steps_per_s"], r["rejax"]["steps_per_s"], r["ratio_smjax_over_rejax"],
          r["smjax"]["final_return"], r["rejax"]["final_return"], r["smjax"]["compile_s"],
          r["rejax"]["compile_s"]] for r in results])
    summary = {"benchmark": "ppo_vs_rejax", "config": {k: v for k, v in vars(args).items() if k != "json"},
               "machine": _common.machine(), "versions": _common.versions("gymnax", "rejax", "smjax"),
               "results": results}
    _common.write_json(args.json, summary)
    print(json_line(summary))
    return summary


def json_line(summary: dict) -> str:
    import json

    short = {"benchmark": summary["benchmark"], "loadavg": summary["machine"]["loadavg_1_5_15"],
             "results": {r["env"]: {"smjax_sps": round(r["smjax"]["steps_per_s"]),
                                    "rejax_sps": round(r["rejax"]["steps_per_s"]),
                                    "ratio": round(r["ratio_smjax_over_rejax"], 3),
                                    "smjax_return": round(r["smjax"]["final_return"], 2),
                                    "rejax_return": round(r["rejax"]["final_return"], 2)}
                         for r in summary["results"]}}
    return json.dumps(short)


if __name__ == "__main__":
    main()
