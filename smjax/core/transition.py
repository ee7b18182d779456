"""The record of one tick that the rollout machinery hands a learner.

It sits in core, below both ``smjax.options`` (which produces transitions) and
``smjax.agents`` (which trains on them), so that imports run one way.

A rollout is a sequence of *ticks*; in every tick every environment takes one primitive
step. The learner does not decide in every tick: while an option it called is running
(or while the levels above have not yet called the learner's template) other policies
act. ``Transition.decision`` marks the ticks where the learner chose; rewards and
discounts of the ticks in between belong to the learner's previous decision, which is
how an option that ran k ticks earns ``sum_i gamma^i r_i`` and a ``gamma^k`` bootstrap
(SMDP). ``discount`` is per tick: ``gamma`` normally, ``gamma**d`` for a tick in which a
template was teleported (d = the template's nominal duration).
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


class Transition(NamedTuple):
    """One tick of B environments (leading axes [T, B] inside a rollout)."""

    obs: jax.Array          # observation before the tick's step
    action: jax.Array       # int32 action index the learner chose (meaningful where decision)
    action_mask: jax.Array  # bool [A]: actions the learner could choose at this tick
    log_prob: jax.Array     # behaviour log-probability of ``action``
    value: jax.Array        # learner's value estimate of ``obs``
    decision: jax.Array     # bool: the learner decided at this tick
    reward: jax.Array       # learner reward received after this tick's step
    discount: jax.Array     # per-tick discount factor (gamma or gamma**d)
    done: jax.Array         # bool: the learner's episode ended after this tick
    # a recurrent learner's memory entering this tick ([H]; None for memoryless learners)
    hidden: jax.Array | None = None


class ActOutput(NamedTuple):
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array


def no_pending(obs: jax.Array, num_actions: int, hidden_size: int = 0) -> Transition:
    """The empty pending row for a batch (``obs [B, ...]``): no decision, reward 0, discount 1.

    A *pending* row is a learner decision whose option was still running when a rollout
    ended; it is carried into the next rollout (``smjax.agents.smdp.carry_pending``).
    """
    batch = obs.shape[:1]
    return Transition(
        obs=jnp.zeros_like(obs), action=jnp.zeros(batch, jnp.int32),
        action_mask=jnp.ones(batch + (int(num_actions),), bool),
        log_prob=jnp.zeros(batch, jnp.float32), value=jnp.zeros(batch, jnp.float32),
        decision=jnp.zeros(batch, bool), reward=jnp.zeros(batch, jnp.float32),
        discount=jnp.ones(batch, jnp.float32), done=jnp.zeros(batch, bool),
        hidden=jnp.zeros(batch + (hidden_size,), jnp.float32) if hidden_size else None)
