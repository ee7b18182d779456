"""The pieces of PPO's update that a single learner's update (``ppo.make_agent``) and
every option's at once (``ppo_options``) share, so that both compute the same thing:
the decisions' advantages and returns, the order decisions are dealt to minibatches in,
the loss, and the new state with its metrics."""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.agents.base import Transition
from smjax.agents.networks import masked_entropy, masked_log_softmax, masked_mean, take_action
from smjax.agents.smdp import complete_decisions, episodes_with_decision, smdp_gae


# Fewest random bits per item for the one-key sort; below them, ties (broken by index)
# would be common enough to matter, so the order falls back to a two-operand argsort.
MIN_NOISE_BITS = 16


def decision_order(key: jax.Array, decision: jax.Array) -> jax.Array:
    """int ``[N]``: every item, the decisions first in a random order (then the others);
    the decision at rank r goes to minibatch r % M (``ppo.minibatch_indices``).

    One uint32 key per item, "not a decision" in the top bit, random bits next and the
    item's index in the low bits, sorted alone: a one-operand sort runs ~5x faster on
    a CPU than an argsort (a key and an index sorted together), and the index comes
    back from the low bits. Ties of the random bits go by index, a bias of order
    N^2 / 2^(noise bits) pairs that the 16 bits or more kept make negligible."""
    n = decision.shape[0]
    index_bits = max(1, (n - 1).bit_length())
    noise_bits = 31 - index_bits
    if noise_bits < MIN_NOISE_BITS:
        noise = jax.random.uniform(key, decision.shape)
        return jnp.argsort(jnp.where(decision, noise, noise + 2.0))
    noise = jax.random.bits(key, decision.shape, jnp.uint32) >> (32 - noise_bits)
    return _sorted_by_packed_key(decision, noise, index_bits)


def decisions_first(decision: jax.Array) -> jax.Array:
    """int ``[N]``: the decisions in their own order, then the other items: the one-operand
    sort of ``decision_order`` with no noise."""
    index_bits = max(1, (decision.shape[0] - 1).bit_length())
    return _sorted_by_packed_key(decision, jnp.zeros(decision.shape, jnp.uint32), index_bits)


def _sorted_by_packed_key(decision: jax.Array, noise: jax.Array, index_bits: int) -> jax.Array:
    """The items' indices ordered by (not a decision, ``noise``, index): one uint32 key per
    item, sorted alone, the index read back from its low ``index_bits`` bits."""
    packed = (((~decision).astype(jnp.uint32) << 31) | (noise << index_bits)
              | jnp.arange(decision.shape[0], dtype=jnp.uint32))
    return (jnp.sort(packed) & ((1 << index_bits) - 1)).astype(jnp.int32)


def num_actions_of(params) -> int:
    """The actions a policy network's parameters score (its policy head's outputs; a
    leading axis of stacked parameters leaves it as it is)."""
    return params["params"]["policy_head"]["kernel"].shape[-1]


def decision_data(config, traj: Transition, hp) -> tuple[tuple, jax.Array]:
    """What the loss reads of a rollout ``[T, B]``, apart from the observations:
    ``(action, mask, old log-prob, old value, advantage, return, decision)``, the
    decisions being the complete ones (``smjax.agents.smdp``); and the episodes in which
    the learner decided."""
    decision = traj.decision.astype(bool)
    adv, ret = smdp_gae(traj.reward, traj.discount, traj.done, decision,
                        jnp.where(decision, traj.value, 0.0), hp["gae_lambda"])
    episodes = episodes_with_decision(traj.done, decision)
    decision = complete_decisions(traj.done, decision)
    if config.normalize_advantages:
        mean = masked_mean(adv, decision)
        var = masked_mean(jnp.square(adv - mean), decision)
        adv = jnp.where(decision, (adv - mean) / (jnp.sqrt(var) + 1e-8), 0.0)
    # Fields of non-decision ticks are unspecified (may be NaN): zero them so that no
    # NaN can reach a gradient through the weight-0 entries.
    unused_to_zero = lambda x: jnp.where(decision, x, 0)  # noqa: E731
    data = (unused_to_zero(traj.action).astype(jnp.int32), traj.action_mask.astype(bool),
            unused_to_zero(traj.log_prob).astype(jnp.float32),
            unused_to_zero(traj.value).astype(jnp.float32), adv, ret, decision)
    return data, episodes


def weighted_sum(values: jax.Array, weights: jax.Array) -> jax.Array:
    """``sum(values * weights)`` over entries of positive weight: a part of a mean whose
    weights are 1 / (the mean's count), so that parts add up to it."""
    return jnp.sum(jnp.where(weights > 0, values * weights, 0.0))


def loss_terms(config, logits, value, batch, hp, mean=masked_mean):
    """PPO's loss and its parts for ``batch = (action, mask, old log-prob, old value,
    advantage, return, weight)``; every term is ``mean(per-item term, weight)``."""
    action, mask, old_log_prob, old_value, adv, ret, weight = batch
    log_prob = take_action(masked_log_softmax(logits, mask), action)
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    clip_eps = hp["clip_eps"]
    clipped = jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps)
    policy_loss = mean(-jnp.minimum(ratio * adv, clipped * adv), weight)
    value_err = jnp.square(value - ret)
    if config.clip_value_loss:
        value_clipped = old_value + jnp.clip(value - old_value, -clip_eps, clip_eps)
        value_err = jnp.maximum(value_err, jnp.square(value_clipped - ret))
    value_loss = 0.5 * mean(value_err, weight)
    entropy = mean(masked_entropy(logits, mask), weight)
    total = policy_loss + hp["vf_coef"] * value_loss - hp["ent_coef"] * entropy
    aux = {
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": entropy,
        # (r - 1) - log r: a low-variance, non-negative estimate of KL(old || new).
        "approx_kl": mean((ratio - 1.0) - log_ratio, weight),
        "clip_fraction": mean((jnp.abs(ratio - 1.0) > clip_eps).astype(jnp.float32), weight),
    }
    return total, aux


def apply_if(pred: jax.Array, new, old):
    """Keep ``old`` when ``pred`` is False (a step with nothing to learn from)."""
    return jax.tree.map(lambda n, o: jnp.where(pred, n, o), new, old)


def kl_stop(stopped, has_decision, approx_kl, hp):
    """Past the drift limit (``PPOConfig.target_kl``), this minibatch and every later one
    leave the parameters alone; the KL is that of the parameters before this step."""
    target_kl = hp["target_kl"]
    return stopped | (has_decision & (target_kl > 0) & (approx_kl > 1.5 * target_kl))


def finish(state, params, opt_state, grad_steps, stopped, aux, episodes, data):
    """The new learner state and the update's metrics; ``aux``: every minibatch step's
    loss parts and ``counted`` (it had a decision), ``data``: ``decision_data``'s."""
    *_, adv, ret, decision = data
    counted = aux.pop("counted")
    metrics = {name: masked_mean(value, counted) for name, value in aux.items()}
    num_decisions = decision.sum().astype(jnp.int32)
    new_state = state.replace(
        params=params, opt_state=opt_state, grad_steps=grad_steps, updates=state.updates + 1,
        episodes_seen=state.episodes_seen + episodes,
        decisions_seen=state.decisions_seen + num_decisions)
    metrics.update(
        decisions=num_decisions,
        mean_advantage=masked_mean(adv, decision),
        mean_return=masked_mean(ret, decision),
        episodes_seen=new_state.episodes_seen,
        grad_steps=grad_steps,
        kl_stopped=stopped.astype(jnp.float32),
    )
    return new_state, metrics
