"""Semi-Markov returns over a rollout in which the learner decides only on some ticks.

Layout: every array is ``[T, B]`` (ticks x environments). On tick t the learner may
decide (``decision[t]``); every tick carries the learner's reward ``reward[t]`` received
after that tick's step, a per-tick discount ``discount[t]`` (gamma, or gamma**d for a
teleported template) and ``done[t]`` (the learner's episode ended after tick t: terminal,
no bootstrap). A decision at tick t whose next decision is at tick t + k earns

    R_t = r_t + g_t r_{t+1} + g_t g_{t+1} r_{t+2} + ... + (g_t ... g_{t+k-2}) r_{t+k-1}
    D_t = g_t g_{t+1} ... g_{t+k-1}          (0 if the episode ends on the way)

and the one-decision TD error is ``delta_t = R_t + D_t V(s_{t+k}) - V(s_t)``.

Everything is one reverse ``lax.scan`` whose carry holds "what follows the current tick
up to the next decision": the discounted reward sum and discount product accumulated so
far, and the next decision's value / advantage / observation. A non-decision tick folds
itself into the carry; a decision tick consumes it and becomes the new boundary. A done
tick cuts the carry (what follows belongs to the next episode), so rewards of ticks
before the learner's first decision of an episode can never reach the previous episode.

Rollout-end approximation: a decision still pending at the last tick (no later decision,
no episode end) bootstraps from ``last_value``, the learner's value of the observation
after the last tick, even though that state need not be a decision state of the learner
(an option it called may still be running). The trainer supplies it; it is exact when the
learner decides on every tick (flat training).
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


def _tick_accumulate(carry_reward, carry_discount, reward, discount, done):
    """Fold one tick into the "until the next decision" accumulators."""
    cont = 1.0 - done.astype(jnp.float32)
    smdp_reward = reward + discount * cont * carry_reward
    smdp_discount = discount * cont * carry_discount
    return smdp_reward, smdp_discount


def smdp_gae(
    traj_reward: jax.Array,
    discount: jax.Array,
    done: jax.Array,
    decision: jax.Array,
    value: jax.Array,
    last_value: jax.Array,
    lam: float | jax.Array,
) -> tuple[jax.Array, jax.Array]:
    """Generalised advantage estimation across SMDP decisions.

    ``A_t = delta_t + D_t * lam * A_next`` with ``A_next`` the advantage of the next
    decision (0 past the rollout end or after an episode end). Returns
    ``(advantages, returns)`` of shape ``[T, B]``, ``returns = advantages + value``; both
    are 0 on non-decision ticks. ``lam = 1`` gives SMDP Monte-Carlo returns bootstrapped
    only at the rollout end.
    """
    reward = traj_reward.astype(jnp.float32)
    discount = discount.astype(jnp.float32)
    value = value.astype(jnp.float32)
    decision = decision.astype(bool)
    lam = jnp.asarray(lam, jnp.float32)

    def step(carry, tick):
        acc_reward, acc_discount, next_value, next_adv = carry
        r, g, d, dec, v = tick
        smdp_reward, smdp_discount = _tick_accumulate(acc_reward, acc_discount, r, g, d)
        delta = smdp_reward + smdp_discount * next_value - v
        adv = delta + smdp_discount * lam * next_adv
        new_carry = (
            jnp.where(dec, 0.0, smdp_reward),
            jnp.where(dec, 1.0, smdp_discount),
            jnp.where(dec, v, next_value),
            jnp.where(dec, adv, next_adv),
        )
        adv_out = jnp.where(dec, adv, 0.0)
        return new_carry, (adv_out, jnp.where(dec, adv + v, 0.0))

    batch = reward.shape[1:]
    init = (
        jnp.zeros(batch, jnp.float32),
        jnp.ones(batch, jnp.float32),
        last_value.astype(jnp.float32),
        jnp.zeros(batch, jnp.float32),
    )
    _, (advantages, returns) = jax.lax.scan(
        step, init, (reward, discount, done, decision, value), reverse=True
    )
    return advantages, returns


class SMDPTransitions(NamedTuple):
    """Per tick ``[T, B, ...]``; meaningful where ``valid`` (= the learner decided there)."""

    reward: jax.Array       # R_t, the discounted reward sum until the next decision
    discount: jax.Array     # D_t without the terminal cut: product of the k tick discounts
    terminal: jax.Array     # an episode ended before the next decision (no bootstrap)
    next_obs: jax.Array     # observation of the next decision (last_obs at the rollout end)
    next_mask: jax.Array    # allowed actions at the next decision (all True at rollout end)
    complete: jax.Array     # the next decision (or the episode end) lies inside the rollout
    valid: jax.Array        # the learner decided on this tick


def smdp_transitions(
    traj_reward: jax.Array,
    discount: jax.Array,
    done: jax.Array,
    decision: jax.Array,
    obs: jax.Array,
    action_mask: jax.Array,
    last_obs: jax.Array,
) -> SMDPTransitions:
    """Pair each decision with its SMDP reward, discount product, next decision and end flag.

    For Q-learning: the target of a decision at tick t is
    ``reward + discount * (1 - terminal) * max_{a' in next_mask} Q(next_obs, a')``.
    A decision pending at the rollout end gets ``next_obs = last_obs`` and an all-True
    ``next_mask`` (the mask there is unknown), and ``complete = False``.
    """
    reward = traj_reward.astype(jnp.float32)
    discount = discount.astype(jnp.float32)
    done = done.astype(bool)
    decision = decision.astype(bool)
    num_actions = action_mask.shape[-1]

    def step(carry, tick):
        acc_reward, acc_discount, acc_terminal, nxt_obs, nxt_mask, nxt_complete = carry
        r, g, d, dec, o, m = tick
        # Keep the raw discount product separate from the terminal flag so a target can
        # be inspected (and reproduced) without the product silently becoming 0.
        smdp_reward = r + g * jnp.where(d, 0.0, acc_reward)
        smdp_discount = g * jnp.where(d, 1.0, acc_discount)
        terminal = jnp.logical_or(d, acc_terminal)
        complete = jnp.logical_or(d, nxt_complete)
        out = (smdp_reward, smdp_discount, terminal, nxt_obs, nxt_mask, complete)
        new_carry = (
            jnp.where(dec, 0.0, smdp_reward),
            jnp.where(dec, 1.0, smdp_discount),
            jnp.where(dec, False, terminal),
            _where_batch(dec, o, nxt_obs),
            _where_batch(dec, m, nxt_mask),
            jnp.where(dec, True, complete),
        )
        return new_carry, out

    batch = reward.shape[1:]
    init = (
        jnp.zeros(batch, jnp.float32),
        jnp.ones(batch, jnp.float32),
        jnp.zeros(batch, bool),
        last_obs.astype(obs.dtype),
        jnp.ones(batch + (num_actions,), bool),
        jnp.zeros(batch, bool),
    )
    _, (r_out, g_out, term_out, next_obs, next_mask, complete) = jax.lax.scan(
        step, init, (reward, discount, done, decision, obs, action_mask), reverse=True
    )
    return SMDPTransitions(r_out, g_out, term_out, next_obs, next_mask, complete, decision)


def _where_batch(pred: jax.Array, on_true: jax.Array, on_false: jax.Array) -> jax.Array:
    """``jnp.where`` with ``pred [B]`` broadcast over the trailing axes of ``[B, ...]``."""
    pred = pred.reshape(pred.shape + (1,) * (on_true.ndim - pred.ndim))
    return jnp.where(pred, on_true, on_false)


def episodes_with_decision(done: jax.Array, decision: jax.Array) -> jax.Array:
    """Number of finished episodes ``[T, B] -> scalar`` in which the learner decided.

    An episode counts when its ``done`` tick is preceded (inclusively) by a decision since
    the previous ``done`` of the same environment. The first segment of each environment
    counts as decided: it continues an episode begun in an earlier rollout, whose
    decisions this rollout cannot see (the learner's episodes start with its decision).
    """
    done = done.astype(bool)
    decision = decision.astype(bool)

    def step(decided_in_episode, tick):
        d, dec = tick
        decided = jnp.logical_or(decided_in_episode, dec)
        counted = jnp.logical_and(d, decided)
        return jnp.where(d, False, decided), counted

    init = jnp.ones(done.shape[1:], bool)
    _, counted = jax.lax.scan(step, init, (done, decision))
    return counted.sum().astype(jnp.int32)
