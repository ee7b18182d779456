"""The pieces of the actor-critic's update that a single learner's update
(``actor_critic.make_agent``) and every option's at once (``actor_critic_options``)
share, so that both compute the same thing: the decisions and their returns, the loss,
the gradient step and the new state with its metrics (the algorithm: ``actor_critic``)."""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import optax

from smjax.agents.base import Transition, scale_by_lr
from smjax.agents.networks import (flatten_obs, masked_entropy, masked_log_softmax, masked_mean,
                                   take_action)
from smjax.agents.smdp import complete_decisions, episodes_with_decision, smdp_gae
from smjax.agents.ppo_update import apply_if


def exploration_epsilon(config, episodes_seen: jax.Array) -> jax.Array:
    decayed = jnp.exp(-config.epsilon_decay * episodes_seen.astype(jnp.float32))
    return jnp.maximum(decayed, config.epsilon_min)


def decision_data(config, traj: Transition) -> tuple[jax.Array, jax.Array, jax.Array]:
    """What the update reads of a rollout ``[T, B]`` apart from the network: the SMDP
    Monte-Carlo returns ``[T, B]``, the complete decisions (bool ``[T, B]``, those it
    trains on, ``smjax.agents.smdp``) and the episodes in which the learner decided."""
    decision = traj.decision.astype(bool)
    _, returns = smdp_gae(traj.reward, traj.discount, traj.done, decision,
                          jnp.where(decision, traj.value, 0.0), 1.0,
                          bootstrap=config.bootstrap_at_rollout_end)
    episodes = episodes_with_decision(traj.done, decision)
    return returns, complete_decisions(traj.done, decision), episodes


def reinforce_terms(config, logits, value, action, mask, returns, weight, hp,
                    mean=masked_mean, advantage_stats=None):
    """(total loss, its terms), each a ``mean(per-item term, weight)`` (the module doc of
    ``actor_critic``). With ``normalize_advantages``, ``advantage_stats`` (mean, std) are
    those of every decision's advantage, given where ``weight`` covers only some of them;
    None: computed from this batch."""
    log_prob = take_action(masked_log_softmax(logits, mask), action)
    advantage = jax.lax.stop_gradient(returns - value)
    if config.normalize_advantages:
        if advantage_stats is None:
            adv_mean = masked_mean(advantage, weight)
            std = jnp.sqrt(masked_mean(jnp.square(advantage - adv_mean), weight))
        else:
            adv_mean, std = advantage_stats
        advantage = (advantage - adv_mean) / (std + 1e-8)
    policy_loss = mean(-log_prob * advantage, weight)
    value_loss = 0.5 * mean(jnp.square(value - returns), weight)
    entropy = mean(masked_entropy(logits, mask), weight)
    total = policy_loss + hp["vf_coef"] * value_loss - hp["ent_coef"] * entropy
    return total, {"policy_loss": policy_loss, "value_loss": value_loss, "entropy": entropy}


def reinforce_loss(config, network_for, params, obs, action, mask, returns, weight, hp):
    """(total loss, its terms) over the decisions ``weight`` marks."""
    logits, value = network_for(mask.shape[-1]).apply(params, obs)
    return reinforce_terms(config, logits, value, action, mask, returns, weight, hp)


def gradient_step(optimizer, state, grads, has_decision: jax.Array):
    """(params, opt_state) after one step on ``grads``; the old ones without a decision
    (nothing to learn: Adam's moments must not drift on a zero gradient)."""
    updates, new_opt_state = optimizer.update(grads, state.opt_state, state.params)
    updates = scale_by_lr(updates, state.hp["learning_rate"])
    new_params = optax.apply_updates(state.params, updates)
    return apply_if(has_decision, (new_params, new_opt_state), (state.params, state.opt_state))


def finish(config, state, params, opt_state, has_decision, episodes, decision, returns,
           total, aux):
    """The new learner state and the update's metrics (``aux``: the loss's terms)."""
    num_decisions = decision.sum().astype(jnp.int32)
    new_state = state.replace(
        params=params,
        opt_state=opt_state,
        grad_steps=state.grad_steps + has_decision.astype(jnp.int32),
        updates=state.updates + 1,
        episodes_seen=state.episodes_seen + episodes,
        decisions_seen=state.decisions_seen + num_decisions,
    )
    metrics = dict(aux, total_loss=total, decisions=num_decisions,
                   mean_return=masked_mean(returns, decision),
                   episodes_seen=new_state.episodes_seen,
                   epsilon=exploration_epsilon(config, new_state.episodes_seen),
                   grad_steps=new_state.grad_steps)
    return new_state, metrics


def reinforce_update(config, network_for, optimizer, state, traj: Transition):
    """One gradient step on the rollout's complete decisions: (new state, metrics)."""
    traj = jax.tree.map(jnp.asarray, traj)  # numpy inputs too
    num_ticks, num_envs = traj.reward.shape[:2]
    returns, decision, episodes = decision_data(config, traj)
    num_items = num_ticks * num_envs
    obs = flatten_obs(traj.obs, batch_dims=2).reshape(num_items, -1)
    action = jnp.where(decision, traj.action, 0).reshape(num_items).astype(jnp.int32)
    mask = traj.action_mask.reshape(num_items, -1).astype(bool)
    weight = decision.reshape(num_items)
    loss_fn = functools.partial(reinforce_loss, config, network_for)
    (total, aux), grads = jax.value_and_grad(loss_fn, has_aux=True)(
        state.params, obs, action, mask, returns.reshape(num_items), weight, state.hp)
    has_decision = jnp.any(decision)
    params, opt_state = gradient_step(optimizer, state, grads, has_decision)
    return finish(config, state, params, opt_state, has_decision, episodes, decision, returns,
                  total, aux)
