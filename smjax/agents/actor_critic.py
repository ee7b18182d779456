"""The paper's learner: REINFORCE with a learned baseline and decaying epsilon exploration.

Reference setting (Sticky Mittens, Craft): one hidden layer of 100 units, Adam 1e-3,
gamma 0.99 (gamma**d on teleported template calls), exploration
``epsilon = exp(-5e-3 * episodes_seen)``: with probability epsilon a uniformly random
*allowed* action, otherwise a sample from the policy.

Returns are SMDP Monte-Carlo returns (``smdp_gae`` with ``lam = 1``): 0 bootstrap at an
episode end. A decision still open at the rollout end is not trained here (the caller
carries it into the next rollout, see :mod:`smjax.agents.smdp`); the decisions before it
bootstrap from the critic's value of its state (``bootstrap_at_rollout_end=True``) or
from 0 (the reference updated only after whole episodes, so it never needed either).
One gradient step per ``update`` call; the reference updated once per 20 episodes, which
the trainer reproduces by choosing the rollout length.

Every loss is a mean over decision ticks: ``-log pi(a|s) * (G - V(s))`` (baseline held
fixed), ``vf_coef * 0.5 * (G - V(s))**2``, minus ``ent_coef * entropy``.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optax

from smjax.agents import config as checks
from smjax.agents.actor_critic_options import make_update_options
from smjax.agents.actor_critic_update import exploration_epsilon, reinforce_update
from smjax.agents.base import ActOutput, Agent, Transition, hyper_params
from smjax.agents.config import static, traced
from smjax.agents.networks import torso_grids
from smjax.agents.ppo import (
    PolicyGradientState,
    init_policy_gradient_state,
    logits_of,
    make_network,
    sample_actions,
)


@dataclass(frozen=True)
class ActorCriticConfig:
    """The actor-critic's settings; ``traced`` ones are read from ``state.hp`` and may be
    swept, ``static`` ones build the program (:mod:`smjax.agents.config`)."""

    learning_rate: float = traced(1e-3)
    gamma: float = static(0.99)
    hidden_sizes: tuple[int, ...] = static((100,))
    activation: str = static("relu")
    shared_torso: bool = static(False)
    # "conv": convolutions over the observation's declared grids, as PPOConfig's
    torso: str = static("mlp")
    conv_features: tuple[int, ...] = static((16, 16))
    epsilon_decay: float = static(5e-3)  # epsilon = max(epsilon_min, exp(-epsilon_decay * episodes))
    epsilon_min: float = static(0.0)
    vf_coef: float = traced(0.5)
    ent_coef: float = traced(0.0)
    max_grad_norm: float = static(0.0)  # 0 disables clipping (the reference did not clip)
    normalize_advantages: bool = static(False)
    bootstrap_at_rollout_end: bool = static(True)
    # how joint fine-tuning updates its learners, as PPOConfig's option_update: "grouped"
    # (every option's one step on its own decisions, ``actor_critic_options``, in blocks
    # of option_block rows), "per_option" (each option's update over every row, vmapped)
    # or "auto" (grouped; benchmarks/RESULTS.md, "The cost of a joint update")
    option_update: str = static("auto")
    option_block: int = static(128)
    option_blocks_per_step: int = static(0)  # as PPOConfig's

    def __post_init__(self):
        checks.check_range(self, "learning_rate", 0.0, 1.0, low_open=True)
        checks.check_range(self, "gamma", 0.0, 1.0)
        checks.check_hidden_sizes(self)
        checks.check_torso(self)
        checks.check_choice(self, "activation", ("tanh", "relu", "gelu", "elu", "swish"))
        checks.check_range(self, "epsilon_decay", 0.0)
        checks.check_range(self, "epsilon_min", 0.0, 1.0)
        checks.check_range(self, "vf_coef", 0.0)
        checks.check_range(self, "ent_coef", 0.0)
        checks.check_range(self, "max_grad_norm", 0.0)
        checks.check_choice(self, "option_update", ("auto", "grouped", "per_option"))
        checks.check_positive_int(self, "option_block")
        checks.check_non_negative_int(self, "option_blocks_per_step")




def make_agent(config: ActorCriticConfig | None = None, layout=()) -> Agent:
    """``layout``: the observation's grids, read by a "conv" torso (``ppo.make_agent``)."""
    config = ActorCriticConfig() if config is None else config
    adam = optax.scale_by_adam()  # the learning rate comes from state.hp (scale_by_lr)
    optimizer = (
        optax.chain(optax.clip_by_global_norm(config.max_grad_norm), adam)
        if config.max_grad_norm > 0
        else adam
    )

    def network_for(num_actions: int):
        return make_network(num_actions, config.hidden_sizes, config.activation, config.shared_torso,
                            torso_grids(config.torso, layout), config.conv_features)

    def init(key: jax.Array, example_obs: jax.Array, num_actions: int) -> PolicyGradientState:
        return init_policy_gradient_state(network_for, optimizer, key, example_obs, num_actions,
                                          hyper_params(config))

    def act(state: PolicyGradientState, obs: jax.Array, mask: jax.Array, key: jax.Array) -> ActOutput:
        epsilon = exploration_epsilon(config, state.episodes_seen)
        return sample_actions(network_for, state.params, obs, mask, key, epsilon)

    def policy_logits(params, obs: jax.Array) -> jax.Array:
        return logits_of(network_for, params, obs)

    def update(state: PolicyGradientState, traj: Transition, key: jax.Array):
        del key  # the update is deterministic given the rollout
        return reinforce_update(config, network_for, optimizer, state, traj)

    def warm_start(state: PolicyGradientState, params) -> PolicyGradientState:
        # exploration at the end of its decay, as the trained policy left it
        seen = jnp.asarray(np.iinfo(np.int32).max // 2, jnp.int32)
        return state.replace(params=params, episodes_seen=seen)

    grouped = config.option_update != "per_option"
    return Agent("actor-critic", init, act, update, policy_logits, "sample", warm_start,
                 update_options=make_update_options(
                     config, network_for, optimizer, config.option_block) if grouped else None)
