"""Flat (non-hierarchical) training of an agent on an ordinary smjax Environment.

PureJaxRL style: ``train = make_train(config, env, env_params, agent)`` is a pure
function of a PRNG key; ``jax.jit(train)(key)`` runs the whole training as one compiled
program and ``jax.vmap(train)(keys)`` trains several seeds at once. Every tick is a
decision of the learner, the reward is the environment's reward, the discount is
``config.gamma`` and ``done = terminated | truncated`` (truncation is treated as terminal,
the common simplification; the auto-reset inside ``env.step`` starts the next episode).
All actions are allowed (the protocol has no action masks). The last tick of a rollout
is a decision whose outcome lies in the next rollout: it is carried there
(``smdp.carry_pending``) and trained as that rollout's row 0.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp

from smjax.agents import config as checks
from smjax.agents.base import Agent, Transition
from smjax.agents.smdp import carry_pending, no_pending
from smjax.core import EpisodeStatistics, spaces


@dataclass(frozen=True)
class FlatTrainConfig:
    num_envs: int = 8
    num_steps: int = 128          # ticks per rollout (T)
    num_updates: int = 100        # rollouts, each followed by one ``agent.update``
    gamma: float = 0.99

    def __post_init__(self):
        for name in ("num_envs", "num_steps", "num_updates"):
            checks.check_positive_int(self, name)
        checks.check_range(self, "gamma", 0.0, 1.0)

    @property
    def total_timesteps(self) -> int:
        return self.num_envs * self.num_steps * self.num_updates


def trainable_actions(env: Any, env_params: Any, agent: Agent) -> int:
    """The number of actions of ``env``'s single Discrete action space; ValueError where
    flat training cannot run (another action space, a recurrent learner)."""
    space = env.action_space(env_params)
    if not isinstance(space, spaces.Discrete) or space.shape != ():
        raise ValueError(f"flat training needs a single Discrete action space, got {space!r}")
    if agent.hidden_size:
        raise ValueError("flat_train runs memoryless learners only; a recurrent learner "
                         f"(hidden_size {agent.hidden_size}) trains through smjax.train "
                         "(`smjax train ... --method flat`)")
    return space.n


def finished_episodes(finished: jax.Array, ep_return: jax.Array, ep_length: jax.Array) -> dict:
    """Mean return and length of the episodes ``finished`` marks (NaN where none), and
    their count."""
    count = finished.sum()
    safe = jnp.maximum(count, 1)
    return dict(
        mean_episode_return=jnp.where(
            count > 0, jnp.sum(jnp.where(finished, ep_return, 0.0)) / safe, jnp.nan),
        mean_episode_length=jnp.where(
            count > 0, jnp.sum(jnp.where(finished, ep_length, 0)) / safe, jnp.nan),
        episodes=count.astype(jnp.int32),
    )


def make_train(
    config: FlatTrainConfig, env: Any, env_params: Any, agent: Agent
) -> Callable[[jax.Array], tuple[Any, dict]]:
    """Returns ``train(key) -> (agent_state, metrics)``; metrics are ``[num_updates]`` arrays.

    ``metrics["mean_episode_return"]`` is the mean undiscounted return of the episodes
    that finished during that update's rollout (NaN when none finished);
    ``metrics["episodes"]`` counts them. The agent's own update metrics are included.
    """
    num_actions = trainable_actions(env, env_params, agent)
    stats_env = EpisodeStatistics(env)

    def train(key: jax.Array):
        key, key_reset, key_init = jax.random.split(key, 3)
        obs, env_state = jax.vmap(stats_env.reset, in_axes=(0, None))(
            jax.random.split(key_reset, config.num_envs), env_params)
        agent_state = agent.init(key_init, obs[0], num_actions)
        mask = jnp.ones((config.num_envs, num_actions), bool)

        def tick(carry, _):
            agent_state, env_state, obs, key = carry
            key, key_act, key_step = jax.random.split(key, 3)
            out = agent.act(agent_state, obs, mask, key_act)
            next_obs, env_state, reward, terminated, truncated, info = jax.vmap(
                stats_env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(key_step, config.num_envs), env_state, out.action, env_params)
            done = jnp.logical_or(terminated, truncated)
            transition = Transition(
                obs=obs, action=out.action, action_mask=mask, log_prob=out.log_prob,
                value=out.value, decision=jnp.ones_like(done),
                reward=reward.astype(jnp.float32),
                discount=jnp.full(done.shape, config.gamma, jnp.float32), done=done)
            episode = (info["returned_episode"], info["episode_return"], info["episode_length"])
            return (agent_state, env_state, next_obs, key), (transition, episode)

        def update_step(carry, _):
            agent_state, env_state, obs, pending, key = carry
            (agent_state, env_state, obs, key), (traj, episode) = jax.lax.scan(
                tick, (agent_state, env_state, obs, key), None, config.num_steps)
            key, key_update = jax.random.split(key)
            traj, pending = carry_pending(pending, traj)
            agent_state, metrics = agent.update(agent_state, traj, key_update)
            metrics = dict(metrics, **finished_episodes(*episode))
            return (agent_state, env_state, obs, pending, key), metrics

        start = (agent_state, env_state, obs, no_pending(obs, num_actions), key)
        (agent_state, *_), metrics = jax.lax.scan(update_step, start, None, config.num_updates)
        return agent_state, metrics

    return train
