"""Learners: PPO, DQN and the paper's actor-critic, all over SMDP decisions.

``make_agent("ppo", learning_rate=3e-4)`` builds an :class:`smjax.agents.base.Agent`
from the algorithm's config dataclass with the given fields overridden::

    agent = make_agent("actor-critic")
    state = agent.init(key, example_obs, num_actions)           # example_obs unbatched
    out = agent.act(state, obs, mask, key)                       # obs [B, ...], mask [B, A]
    state, metrics = agent.update(state, traj, key)              # traj: Transition [T, B]
    logits = agent.policy_logits(state.params, obs)              # greedy scores [B, A]

Flat training on an ordinary environment: ``smjax.agents.flat_train.make_train``.
Returns over decisions: ``smjax.agents.smdp`` (``smdp_gae``, ``smdp_transitions``); a
decision still running at a rollout's end is carried into the next rollout with
``carry_pending`` (the update trains it once it completes).
"""
from __future__ import annotations

from typing import Any, Sequence

from smjax.agents import actor_critic, dqn, ppo
from smjax.agents.actor_critic import ActorCriticConfig
from smjax.agents.base import ActOutput, Agent, Transition
from smjax.agents.config import replace_checked
from smjax.agents.dqn import DQNConfig
from smjax.agents.ppo import PPOConfig
from smjax.agents.smdp import carry_pending, no_pending, smdp_gae, smdp_transitions

ALGOS: tuple[str, ...] = ("ppo", "dqn", "actor-critic")

_CONFIGS = {"ppo": PPOConfig, "dqn": DQNConfig, "actor-critic": ActorCriticConfig}
_MAKERS = {"ppo": ppo.make_agent, "dqn": dqn.make_agent, "actor-critic": actor_critic.make_agent}


def default_config(algo: str) -> Any:
    """The default config dataclass of ``algo``."""
    if algo not in _CONFIGS:
        raise ValueError(f"unknown algo {algo!r}; valid algos: {', '.join(ALGOS)}")
    return _CONFIGS[algo]()


def make_config(algo: str, **config_overrides: Any) -> Any:
    """``algo``'s config with fields overridden (unknown fields and bad values raise ValueError)."""
    return replace_checked(default_config(algo), **config_overrides)


def make_agent(algo: str, layout: Sequence = (), **config_overrides: Any) -> Agent:
    """Build the learner ``algo`` (one of :data:`ALGOS`) with config fields overridden;
    ``layout``: the observation's grids (``Environment.observation_layout``), which a
    ``torso="conv"`` learner reads with convolutions (ValueError where there are none)."""
    config = make_config(algo, **config_overrides)  # validates algo before the lookup below
    return _MAKERS[algo](config, layout)


__all__ = [
    "ALGOS", "make_agent", "make_config", "default_config", "Agent", "ActOutput", "Transition",
    "PPOConfig", "DQNConfig", "ActorCriticConfig", "smdp_gae", "smdp_transitions",
    "carry_pending", "no_pending",
]
