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

**Decisions pending at the rollout end are not trained here.** A decision with neither a
later decision nor an episode end inside the rollout is *incomplete*: the option it
called may still be running, so the state after the last tick is not one where the
learner decides, and bootstrapping from it (with a value or Q-values of a state the
learner never chooses in, and an unknown action mask) biases every long option. Instead
the caller keeps it with :func:`carry_pending` and passes it back as row 0 of the next
rollout, with its reward and discount accumulated so far; it is trained there, once it
completes. Every decision is thus trained exactly once, on its true SMDP target.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from smjax.core.transition import Transition, no_pending  # noqa: F401  (no_pending re-exported)


def _tick_accumulate(carry_reward, carry_discount, reward, discount, done):
    """Fold one tick into the "until the next decision" accumulators."""
    cont = 1.0 - done.astype(jnp.float32)
    smdp_reward = reward + discount * cont * carry_reward
    smdp_discount = discount * cont * carry_discount
    return smdp_reward, smdp_discount


def complete_decisions(done: jax.Array, decision: jax.Array) -> jax.Array:
    """bool ``[T, B]``: decisions followed, inside the rollout, by another decision or an
    episode end (what the learners train on; the others are pending, see the module doc)."""
    done = done.astype(bool)
    decision = decision.astype(bool)

    def step(closed_after, tick):
        d, dec = tick
        closed = jnp.logical_or(d, closed_after)   # this tick's decision (if any) is closed
        return jnp.logical_or(dec, closed), jnp.logical_and(dec, closed)

    _, complete = jax.lax.scan(step, jnp.zeros(done.shape[1:], bool), (done, decision),
                               reverse=True)
    return complete


def smdp_gae(
    traj_reward: jax.Array,
    discount: jax.Array,
    done: jax.Array,
    decision: jax.Array,
    value: jax.Array,
    lam: float | jax.Array,
    bootstrap: bool = True,
) -> tuple[jax.Array, jax.Array]:
    """Generalised advantage estimation across SMDP decisions.

    ``A_t = delta_t + D_t * lam * A_next`` with ``A_next`` the advantage of the next
    decision (0 after an episode end). Returns ``(advantages, returns)`` of shape
    ``[T, B]``, ``returns = advantages + value``; both are 0 on non-decision ticks and on
    incomplete decisions (:func:`complete_decisions`). A decision whose next decision is
    the incomplete one bootstraps from that decision's value (0 when ``bootstrap`` is
    False) and its advantage chain stops there (truncated GAE). ``lam = 1`` gives SMDP
    Monte-Carlo returns bootstrapped only at the pending decision.
    """
    reward = traj_reward.astype(jnp.float32)
    discount = discount.astype(jnp.float32)
    value = value.astype(jnp.float32)
    decision = decision.astype(bool)
    complete = complete_decisions(done, decision)
    lam = jnp.asarray(lam, jnp.float32)

    def step(carry, tick):
        acc_reward, acc_discount, next_value, next_adv = carry
        r, g, d, dec, ok, v = tick
        smdp_reward, smdp_discount = _tick_accumulate(acc_reward, acc_discount, r, g, d)
        delta = smdp_reward + smdp_discount * next_value - v
        adv = jnp.where(ok, delta + smdp_discount * lam * next_adv, 0.0)
        pending_value = v if bootstrap else jnp.zeros_like(v)
        new_carry = (
            jnp.where(dec, 0.0, smdp_reward),
            jnp.where(dec, 1.0, smdp_discount),
            jnp.where(dec, jnp.where(ok, v, pending_value), next_value),
            jnp.where(dec, adv, next_adv),
        )
        trained = jnp.logical_and(dec, ok)
        return new_carry, (jnp.where(trained, adv, 0.0), jnp.where(trained, adv + v, 0.0))

    batch = reward.shape[1:]
    init = (jnp.zeros(batch, jnp.float32), jnp.ones(batch, jnp.float32),
            jnp.zeros(batch, jnp.float32), jnp.zeros(batch, jnp.float32))
    _, (advantages, returns) = jax.lax.scan(
        step, init, (reward, discount, done, decision, complete, value), reverse=True
    )
    return advantages, returns


class SMDPTransitions(NamedTuple):
    """Per tick ``[T, B, ...]``; meaningful where ``valid`` (complete decisions)."""

    reward: jax.Array       # R_t, the discounted reward sum until the next decision
    discount: jax.Array     # D_t without the terminal cut: product of the k tick discounts
    terminal: jax.Array     # an episode ended before the next decision (no bootstrap)
    next_obs: jax.Array     # observation of the next decision
    next_mask: jax.Array    # allowed actions at the next decision
    valid: jax.Array        # a complete decision of the learner on this tick


def smdp_transitions(
    traj_reward: jax.Array,
    discount: jax.Array,
    done: jax.Array,
    decision: jax.Array,
    obs: jax.Array,
    action_mask: jax.Array,
) -> SMDPTransitions:
    """Pair each decision with its SMDP reward, discount product, next decision and end flag.

    For Q-learning: the target of a decision at tick t is
    ``reward + discount * (1 - terminal) * max_{a' in next_mask} Q(next_obs, a')``.
    Incomplete decisions are not ``valid`` (their next decision lies in a later rollout).
    """
    reward = traj_reward.astype(jnp.float32)
    discount = discount.astype(jnp.float32)
    done = done.astype(bool)
    decision = decision.astype(bool)

    def step(carry, tick):
        acc_reward, acc_discount, acc_terminal, nxt_obs, nxt_mask = carry
        r, g, d, dec, o, m = tick
        # Keep the raw discount product separate from the terminal flag so a target can
        # be inspected (and reproduced) without the product silently becoming 0.
        smdp_reward = r + g * jnp.where(d, 0.0, acc_reward)
        smdp_discount = g * jnp.where(d, 1.0, acc_discount)
        terminal = jnp.logical_or(d, acc_terminal)
        out = (smdp_reward, smdp_discount, terminal, nxt_obs, nxt_mask)
        new_carry = (
            jnp.where(dec, 0.0, smdp_reward),
            jnp.where(dec, 1.0, smdp_discount),
            jnp.where(dec, False, terminal),
            _where_batch(dec, o, nxt_obs),
            _where_batch(dec, m, nxt_mask),
        )
        return new_carry, out

    batch = reward.shape[1:]
    # Placeholders for decisions with nothing after them (incomplete): never valid.
    init = (jnp.zeros(batch, jnp.float32), jnp.ones(batch, jnp.float32), jnp.zeros(batch, bool),
            jnp.zeros_like(obs[0]), jnp.zeros_like(action_mask[0], bool))
    _, (r_out, g_out, term_out, next_obs, next_mask) = jax.lax.scan(
        step, init, (reward, discount, done, decision, obs, action_mask), reverse=True
    )
    valid = complete_decisions(done, decision)
    return SMDPTransitions(r_out, g_out, term_out, next_obs, next_mask, valid)


def carry_pending(pending: Transition, traj: Transition) -> tuple[Transition, Transition]:
    """Prepend last rollout's pending decisions; return this rollout's.

    ``pending`` is a ``Transition[B]`` row (from :func:`no_pending` or a previous call):
    where ``decision`` is set it is a learner decision whose option had not finished,
    with ``reward``/``discount`` the discounted reward sum and discount product of all its
    ticks so far. Returns ``(traj_with_row0 [T+1, B], new_pending [B])``: the update sees
    the pending decision as an ordinary decision tick at row 0, whose later ticks follow in
    this rollout, so its SMDP target is exact once it completes.
    """
    traj = jax.tree.map(lambda p, t: t.astype(p.dtype), pending, traj)
    extended = jax.tree.map(lambda p, t: jnp.concatenate([p[None], t]), pending, traj)

    def step(p: Transition, row: Transition):
        dec = row.decision.astype(bool)
        grown = p._replace(reward=p.reward + p.discount * row.reward,
                           discount=p.discount * row.discount)
        nxt = jax.tree.map(lambda a, b: _where_batch(dec, a, b), row, grown)
        active = jnp.logical_and(jnp.logical_or(p.decision, dec), ~row.done.astype(bool))
        nxt = nxt._replace(decision=active, done=jnp.zeros_like(active),
                           reward=jnp.where(active, nxt.reward, 0.0),
                           discount=jnp.where(active, nxt.discount, 1.0))
        return nxt, None

    empty = no_pending(pending.obs, pending.action_mask.shape[-1],
                       0 if pending.hidden is None else pending.hidden.shape[-1])
    start = jax.tree.map(lambda e, p: e.astype(p.dtype), empty, pending)
    new_pending, _ = jax.lax.scan(step, start, extended)
    return extended, new_pending


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
