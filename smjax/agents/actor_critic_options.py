"""The actor-critic's update for a learner per option at the price of one:
``Agent.update_options``.

The result is that of ``update`` run once per option (one gradient step on the option's
complete decisions, the same metrics; only the order of float sums differs), but each
option's network runs on its own decisions alone: they are gathered from the rollout by
index (the observations from the batch's one table), and every option's gradient comes
from one loop over blocks of its rows (``smjax.agents.grouped``). Each option keeps its
own parameters, optimiser state and hyper-parameters (``state.hp``).

With ``normalize_advantages`` the advantages are centred and scaled by their mean and
spread over all of an option's decisions, which depend on the network's values: a
forward pass over the decisions (``grouped_sums``) gives them before the gradient's.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.agents.actor_critic_update import (decision_data, finish, gradient_step,
                                              reinforce_terms)
from smjax.agents.grouped import blocks_per_step, grouped_grads, grouped_sums
from smjax.agents.networks import flatten_obs, masked_mean
from smjax.agents.option_batch import OptionBatch
from smjax.agents.ppo_update import weighted_sum


def make_update_options(config, network_for, optimizer, block: int):
    """``update_options(states, batch, key)`` for the actor-critic's ``config`` (its
    network from ``network_for``), with ``block`` rows per block of the gradient loop."""

    def update_options(states, batch: OptionBatch, key: jax.Array):
        del key  # the update is deterministic given the rollout
        O, T, B = batch.traj.decision.shape
        per_step = blocks_per_step(config.option_blocks_per_step, T * B, block, O)
        returns, decision, episodes = jax.vmap(lambda tr: decision_data(config, tr))(batch.traj)
        flat = lambda x: x.reshape((O, T * B) + x.shape[3:])  # noqa: E731
        counts = flat(decision).sum(1).astype(jnp.int32)
        # each option's decisions first, in rollout order: its rows 0 .. counts[o] - 1
        order = jnp.argsort(~flat(decision), axis=1, stable=True)
        data = (flat(batch.traj.obs), flat(jnp.where(decision, batch.traj.action, 0)),
                flat(batch.traj.action_mask), flat(returns))
        network = network_for(batch.traj.action_mask.shape[-1])

        def rows_of(own, o, j, valid):
            """Option o's decisions of ranks ``j``: network outputs, their data, weights."""
            item = order[o, jnp.minimum(j, T * B - 1)]
            table_row, action, mask, ret = (x[o, item] for x in data)
            logits, value = network.apply(own, flatten_obs(batch.obs[table_row]))
            weight = jnp.where(valid, 1.0 / jnp.maximum(counts[o], 1), 0.0)
            return (logits, value, action.astype(jnp.int32), mask.astype(bool), ret, weight)

        stats = None
        if config.normalize_advantages:
            stats = advantage_stats(rows_of, states.params, counts, block, per_step,
                                    batch.traj.value, returns, decision)

        def block_loss(own, o, j, valid):
            hp = jax.tree.map(lambda x: x[o], states.hp)
            picked = None if stats is None else (stats[0][o], stats[1][o])
            return reinforce_terms(config, *rows_of(own, o, j, valid), hp, mean=weighted_sum,
                                   advantage_stats=picked)

        grads, sums = grouped_grads(block_loss, states.params, counts, block, per_step)
        total = sums.pop("loss")

        def one_option(state, grads, episodes, decision, returns, total, aux):
            has_decision = jnp.any(decision)
            params, opt_state = gradient_step(optimizer, state, grads, has_decision)
            return finish(config, state, params, opt_state, has_decision, episodes, decision,
                          returns, total, aux)

        return jax.vmap(one_option)(states, grads, episodes, decision, returns, total, sums)

    return update_options


def advantage_stats(rows_of, params, counts, block, per_step, value, returns, decision):
    """The mean and standard deviation ([O] each) of every option's advantages
    ``return - V(s)`` over its decisions. The spread is summed around a shift close to
    the mean (the advantages by the values the rollout recorded), so that the difference
    of the two sums below does not cancel away its digits."""
    shift = jax.vmap(masked_mean)(returns - jnp.where(decision, value, 0.0), decision)

    def block_values(own, o, j, valid):
        _, v, _, _, ret, weight = rows_of(own, o, j, valid)
        centred = ret - v - shift[o]
        return {"mean": weighted_sum(centred, weight),
                "square": weighted_sum(jnp.square(centred), weight)}

    sums = grouped_sums(block_values, params, counts, block, per_step)
    variance = jnp.maximum(sums["square"] - jnp.square(sums["mean"]), 0.0)
    return shift + sums["mean"], jnp.sqrt(variance)
