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

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optax

from smjax.agents import config as checks
from smjax.agents.base import ActOutput, Agent, Transition, hyper_params, scale_by_lr
from smjax.agents.config import static, traced
from smjax.agents.networks import (flatten_obs, masked_entropy, masked_log_softmax, masked_mean,
                                   take_action, torso_grids)
from smjax.agents.ppo import (
    PolicyGradientState,
    init_policy_gradient_state,
    logits_of,
    make_network,
    sample_actions,
)
from smjax.agents.smdp import complete_decisions, episodes_with_decision, smdp_gae


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


def exploration_epsilon(config: ActorCriticConfig, episodes_seen: jax.Array) -> jax.Array:
    decayed = jnp.exp(-config.epsilon_decay * episodes_seen.astype(jnp.float32))
    return jnp.maximum(decayed, config.epsilon_min)


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

    return Agent("actor-critic", init, act, update, policy_logits, "sample", warm_start)


def reinforce_loss(config: ActorCriticConfig, network_for, params, obs, action, mask, returns,
                   weight, hp):
    """(total loss, its terms) over the decisions ``weight`` marks (see the module docstring)."""
    logits, value = network_for(mask.shape[-1]).apply(params, obs)
    log_prob = take_action(masked_log_softmax(logits, mask), action)
    advantage = jax.lax.stop_gradient(returns - value)
    if config.normalize_advantages:
        mean = masked_mean(advantage, weight)
        std = jnp.sqrt(masked_mean(jnp.square(advantage - mean), weight))
        advantage = (advantage - mean) / (std + 1e-8)
    policy_loss = masked_mean(-log_prob * advantage, weight)
    value_loss = 0.5 * masked_mean(jnp.square(value - returns), weight)
    entropy = masked_mean(masked_entropy(logits, mask), weight)
    total = policy_loss + hp["vf_coef"] * value_loss - hp["ent_coef"] * entropy
    return total, {"policy_loss": policy_loss, "value_loss": value_loss, "entropy": entropy}


def reinforce_update(config: ActorCriticConfig, network_for, optimizer,
                     state: PolicyGradientState, traj: Transition):
    """One gradient step on the rollout's complete decisions: (new state, metrics)."""
    traj = jax.tree.map(jnp.asarray, traj)  # numpy inputs too
    num_ticks, num_envs = traj.reward.shape[:2]
    decision = traj.decision.astype(bool)
    _, returns = smdp_gae(traj.reward, traj.discount, traj.done, decision,
                          jnp.where(decision, traj.value, 0.0), 1.0,
                          bootstrap=config.bootstrap_at_rollout_end)
    episodes = episodes_with_decision(traj.done, decision)
    decision = complete_decisions(traj.done, decision)
    num_items = num_ticks * num_envs
    obs = flatten_obs(traj.obs, batch_dims=2).reshape(num_items, -1)
    action = jnp.where(decision, traj.action, 0).reshape(num_items).astype(jnp.int32)
    mask = traj.action_mask.reshape(num_items, -1).astype(bool)
    weight = decision.reshape(num_items)
    loss_fn = functools.partial(reinforce_loss, config, network_for)
    (total, aux), grads = jax.value_and_grad(loss_fn, has_aux=True)(
        state.params, obs, action, mask, returns.reshape(num_items), weight, state.hp)
    updates, new_opt_state = optimizer.update(grads, state.opt_state, state.params)
    updates = scale_by_lr(updates, state.hp["learning_rate"])
    new_params = optax.apply_updates(state.params, updates)
    # With no decision in the rollout there is nothing to learn; do not let Adam's
    # moments drift on a zero gradient.
    has_decision = jnp.any(decision)
    params, opt_state = jax.tree.map(
        lambda n, o: jnp.where(has_decision, n, o),
        (new_params, new_opt_state), (state.params, state.opt_state))
    num_decisions = decision.sum().astype(jnp.int32)
    new_state = PolicyGradientState(
        params=params,
        opt_state=opt_state,
        grad_steps=state.grad_steps + has_decision.astype(jnp.int32),
        updates=state.updates + 1,
        episodes_seen=state.episodes_seen + episodes,
        decisions_seen=state.decisions_seen + num_decisions,
        hp=state.hp,
    )
    metrics = dict(aux, total_loss=total, decisions=num_decisions,
                   mean_return=masked_mean(returns, decision),
                   episodes_seen=new_state.episodes_seen,
                   epsilon=exploration_epsilon(config, new_state.episodes_seen),
                   grad_steps=new_state.grad_steps)
    return new_state, metrics
