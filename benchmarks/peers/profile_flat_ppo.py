"""Where smjax's flat PPO spends its time relative to rejax: rollout vs update, per learner.

Times, for one gymnax environment and one configuration, the compiled
(a) rollout only (``num_updates`` rollouts of ``num_steps`` ticks, no learning) and
(b) update only (``num_updates`` PPO updates on one fixed rollout), for smjax's PPO
and for rejax's PPO (``collect_trajectories`` / the rest of ``train_iteration``)::

    python benchmarks/peers/profile_flat_ppo.py --env CartPole-v1 --num-envs 16 --num-steps 128
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
from ppo_vs_rejax import parse_args as ppo_args  # noqa: E402


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="CartPole-v1")
    p.add_argument("--updates", type=int, default=8, help="rollouts (and updates) per timed program")
    args, rest = p.parse_known_args(argv)
    cfg = ppo_args(rest + ["--envs", args.env])

    import gymnax
    from rejax import PPO

    from smjax.agents import Transition, make_agent
    from smjax.core import EpisodeStatistics
    from smjax.core.adapters import from_gymnax

    genv, gparams = gymnax.make(args.env)
    env, params = from_gymnax(genv, gparams)
    stats_env = EpisodeStatistics(env)
    agent = make_agent("ppo", learning_rate=cfg.lr, update_epochs=cfg.epochs, num_minibatches=cfg.minibatches,
                       hidden_sizes=cfg.hidden, activation=cfg.activation, max_grad_norm=cfg.max_grad_norm,
                       adam_eps=1e-8)
    n, t, u = cfg.num_envs, cfg.num_steps, args.updates
    num_actions = env.action_space(params).n
    key = jax.random.PRNGKey(cfg.seed)
    obs0, state0 = jax.vmap(stats_env.reset, in_axes=(0, None))(jax.random.split(key, n), params)
    agent_state = agent.init(key, obs0[0], num_actions)
    mask = jnp.ones((n, num_actions), bool)

    def smjax_rollout(agent_state, env_state, obs, key):
        def tick(carry, _):
            env_state, obs, key = carry
            key, key_act, key_step = jax.random.split(key, 3)
            out = agent.act(agent_state, obs, mask, key_act)
            nobs, env_state, reward, term, trunc, _ = jax.vmap(stats_env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(key_step, n), env_state, out.action, params)
            done = term | trunc
            tr = Transition(obs=obs, action=out.action, action_mask=mask, log_prob=out.log_prob,
                            value=out.value, decision=jnp.ones_like(done), reward=reward,
                            discount=jnp.full(done.shape, 0.99), done=done)
            return (env_state, nobs, key), tr
        return jax.lax.scan(tick, (env_state, obs, key), None, t)

    def smjax_rollouts(key):
        def body(carry, _):
            carry, traj = smjax_rollout(agent_state, *carry)
            return carry, traj.reward.sum()
        return jax.lax.scan(body, (state0, obs0, key), None, u)[1]

    (_, last_obs, _), traj = jax.jit(smjax_rollout)(agent_state, state0, obs0, key)

    def smjax_updates(key):
        def body(s, k):
            s, m = agent.update(s, traj, last_obs, k)
            return s, m["total_loss"]
        return jax.lax.scan(body, agent_state, jax.random.split(key, u))[1]

    algo = PPO.create(env=genv, env_params=gparams, num_envs=n, num_steps=t, num_epochs=cfg.epochs,
                      num_minibatches=cfg.minibatches, learning_rate=cfg.lr, max_grad_norm=cfg.max_grad_norm,
                      total_timesteps=n * t * u, eval_freq=n * t * u, skip_initial_evaluation=True,
                      agent_kwargs={"activation": cfg.activation, "hidden_layer_sizes": cfg.hidden})

    def rejax_rollouts(key):
        def body(ts, _):
            ts, trajectories = algo.collect_trajectories(ts)
            return ts, trajectories.reward.sum()
        return jax.lax.scan(body, algo.init_state(key), None, u)[1]

    def rejax_iterations(key):
        ts = jax.lax.fori_loop(0, u, lambda _, ts: algo.train_iteration(ts), algo.init_state(key))
        # A value that depends on the learned parameters, so nothing is dead code.
        return sum(jnp.sum(leaf) for leaf in jax.tree.leaves(ts.actor_ts.params))

    rows, out = [], {}
    for name, fn in (("smjax rollout", smjax_rollouts), ("rejax rollout", rejax_rollouts),
                     ("smjax update", smjax_updates), ("rejax rollout+update", rejax_iterations)):
        timing = _common.compile_and_time(fn, (key,), cfg.repeats)
        out[name] = {"median_s": timing["median_s"], "compile_s": timing["compile_s"],
                     "env_steps_per_s": n * t * u / timing["median_s"]}
        rows.append([name, timing["median_s"], n * t * u / timing["median_s"], timing["compile_s"]])
    out["rejax update (derived)"] = {"median_s": out["rejax rollout+update"]["median_s"] - out["rejax rollout"]["median_s"]}
    rows.append(["rejax update (derived)", out["rejax update (derived)"]["median_s"], float("nan"), float("nan")])
    _common.print_table(["program", "median s", "env steps/s", "compile s"], rows)
    summary = {"benchmark": "profile_flat_ppo", "env": args.env, "num_envs": n, "num_steps": t, "updates": u,
               "machine": _common.machine(), "results": out}
    print(json.dumps(summary, default=float))
    return summary


if __name__ == "__main__":
    main()
