"""One rollout's records for a learner per option, with the observation stored once.

Joint fine-tuning trains a learner per option, each on its own record of every tick
(``smjax.options.joint``). The records share the tick's observation; only the pending
rows (an option's decision still running at the last rollout end, carried into this one:
:func:`smjax.agents.smdp.carry_pending`) have an observation of their own. An
:class:`OptionBatch` keeps one table of observations and, per option, a row index into it,
so neither the pending carry nor a learner copies the observations once per option.

An agent may train every option at once (``Agent.update_options``), with work that
follows the decisions in the batch rather than decisions x options; :func:`each_option`
is the fallback that runs ``Agent.update`` once per option over every row.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from smjax.agents.smdp import carry_pending
from smjax.core.transition import Transition


class OptionBatch(NamedTuple):
    """``obs``: the observation table ``[R, ...]`` (a zero row, the rollout's ticks, then
    every option's pending rows); ``traj``: each option's record ``Transition [O, T+1, B]``
    (row 0: its pending decisions) whose ``obs`` is the int32 row in ``obs``."""

    obs: jax.Array
    traj: Transition

    def observations(self) -> jax.Array:
        """``[O, T+1, B, ...]``: every option's observations, copied out of the table."""
        return self.obs[self.traj.obs]


def joint_batch(pending: Transition, traj: Transition) -> tuple[OptionBatch, Transition]:
    """Prepend every option's pending decisions to its record of the rollout.

    ``pending``: ``Transition [O, B]`` (each option's own); ``traj``: a joint record
    ``[T, B, O]`` whose ``obs [T, B, ...]`` is shared (``smjax.options.joint``). Returns the
    batch (option axis first) and the new pending rows ``[O, B]``, as
    ``carry_pending`` gives them option by option."""
    T, B, O = traj.decision.shape
    # row 0 is a zero observation: that of a pending row that never held a decision
    # (``no_pending``'s, whose row index is 0)
    ticks = 1 + jnp.arange(T * B, dtype=jnp.int32).reshape(T, B)
    held = 1 + T * B + jnp.arange(O * B, dtype=jnp.int32).reshape(O, B)
    table = jnp.concatenate([jnp.zeros((1,) + traj.obs.shape[2:], traj.obs.dtype),
                             traj.obs.reshape((T * B,) + traj.obs.shape[2:]),
                             pending.obs.reshape((O * B,) + pending.obs.shape[2:])])

    def option_first(x):
        return None if x is None else jnp.moveaxis(x, 2, 0)

    per_option = traj._replace(obs=None, hidden=None)
    per_option = jax.tree.map(option_first, per_option)._replace(
        obs=jnp.broadcast_to(ticks, (O, T, B)), hidden=_shared(traj.hidden, O))
    rows, new_pending = jax.vmap(carry_pending)(pending._replace(obs=held), per_option)
    new_pending = new_pending._replace(obs=table[new_pending.obs])
    return OptionBatch(table, rows), new_pending


def _shared(x, num_options: int):
    """A field every option shares (``None`` stays ``None``), given an option axis."""
    return None if x is None else jnp.broadcast_to(x, (num_options,) + x.shape)


def each_option(update):
    """``update_options`` from a single learner's ``update``: every option's update over
    every row of its record (the observations copied per option), vmapped over the options.
    Each option gets its own key (``jax.random.split(key, O)``)."""
    def update_options(states, batch: OptionBatch, key: jax.Array):
        traj = batch.traj._replace(obs=batch.observations())
        keys = jax.random.split(key, traj.decision.shape[0])
        return jax.vmap(update)(states, traj, keys)

    return update_options


def options_update(agent):
    """The agent's ``update_options``, or the per-option fallback where it has none."""
    return agent.update_options or each_option(agent.update)
