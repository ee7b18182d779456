"""PPO's update for a learner per option at the price of one: ``Agent.update_options``.

The result is that of ``update`` run once per option with ``jax.random.split(key, O)``
(the same decisions in the same minibatches, the same steps, the same metrics; only the
order of float sums differs), but each option's network runs on its own decisions
alone: an option's minibatch is its decisions of ranks m, m + M, ... in the order
``decision_order`` deals them, gathered from the rollout by index (the observations
from the batch's one table), and every option's gradient of a minibatch comes from one
loop over blocks of its rows (``smjax.agents.grouped``). Each option keeps its own
parameters, optimiser state, hyper-parameters (``state.hp``) and drift stop.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from smjax.agents.base import scale_by_lr
from smjax.agents.grouped import blocks_per_step, grouped_grads, grouped_rows
from smjax.agents.networks import flatten_obs
from smjax.agents.option_batch import OptionBatch
from smjax.agents.ppo_update import (apply_if, decision_data, decision_order, decisions_first,
                                     finish, kl_stop, loss_terms, num_actions_of, weighted_sum)


def make_update_options(config, network_for, optimizer, block: int):
    """``update_options(states, batch, key)`` for PPO's ``config`` (a memoryless network
    from ``network_for``), with ``block`` rows per block of the gradient loop."""
    M = config.num_minibatches

    def option_gradients(states, params, batch: OptionBatch, flat, order, counts, m, per_step):
        """Every option's gradient on its minibatch ``m`` (``counts`` [O] decisions)."""
        rows = batch.traj.obs.reshape(order.shape)
        network = network_for(flat[1].shape[-1])

        def block_loss(own, o, j, valid):
            item = order[o, jnp.minimum(j * M + m, order.shape[1] - 1)]
            obs = flatten_obs(batch.obs[rows[o, item]])
            weight = jnp.where(valid, 1.0 / jnp.maximum(counts[o], 1), 0.0)
            picked = tuple(x[o, item] for x in flat[:-1])
            hp = jax.tree.map(lambda x: x[o], states.hp)
            logits, value = network.apply(own, obs)
            return loss_terms(config, logits, value, picked + (weight,), hp, mean=weighted_sum)

        return grouped_grads(block_loss, params, counts, block, per_step)

    def step(grads, opt_state, params, hp):
        updates, opt_state = optimizer.update(grads, opt_state, params)
        updates = scale_by_lr(updates, hp["learning_rate"])
        return optax.apply_updates(params, updates), opt_state

    def update_options(states, batch: OptionBatch, key: jax.Array):
        O, T, B = batch.traj.decision.shape
        # a minibatch's rows where each tick holds one decision
        per_step = blocks_per_step(config.option_blocks_per_step, T * B // M, block, O)
        data, episodes = jax.vmap(lambda tr, hp: decision_data(config, tr, hp))(
            batch.traj, states.hp)
        flat = tuple(x.reshape((O, T * B) + x.shape[3:]) for x in data)
        decisions = flat[-1].sum(1)

        def minibatch_step(carry, m, order):
            params, opt_state, grad_steps, stopped = carry
            counts = jnp.maximum((decisions - m + M - 1) // M, 0)
            grads, sums = option_gradients(states, params, batch, flat, order, counts, m,
                                           per_step)
            new = jax.vmap(step)(grads, opt_state, params, states.hp)
            has_decision = counts > 0
            stopped = kl_stop(stopped, has_decision, sums["approx_kl"], states.hp)
            stepped = has_decision & ~stopped
            params, opt_state = jax.vmap(apply_if)(stepped, new, (params, opt_state))
            aux = dict(sums, counted=has_decision.astype(jnp.float32))
            aux["total_loss"] = aux.pop("loss")
            return (params, opt_state, grad_steps + stepped.astype(jnp.int32), stopped), aux

        def epoch_step(carry, keys):
            order = jax.vmap(decision_order)(keys, flat[-1])
            return jax.lax.scan(lambda c, m: minibatch_step(c, m, order), carry, jnp.arange(M))

        keys = jax.vmap(lambda k: jax.random.split(k, config.update_epochs))(
            jax.random.split(key, O))
        carry = (states.params, states.opt_state, states.grad_steps, jnp.zeros((O,), bool))
        (params, opt_state, grad_steps, stopped), aux = jax.lax.scan(
            epoch_step, carry, jnp.swapaxes(keys, 0, 1))
        aux = jax.tree.map(lambda x: jnp.moveaxis(x, -1, 0), aux)  # [E, M, O] -> [O, E, M]
        return jax.vmap(finish)(states, params, opt_state, grad_steps, stopped, aux,
                                episodes, data)

    return update_options


def make_option_values(config, network_for):
    """``option_values(states, obs, decision) -> value [T, B, O]``: every option's critic on
    its own decisions of a joint rollout (``obs [T, B, ...]`` shared, ``decision [T, B, O]``),
    0 elsewhere; the values its ``act`` gives there, with the same parameters. None where
    the critic shares the actor's work (a shared or convolutional torso): it runs anyway.

    Why: in a joint rollout every option acts at every tick, but a value is read only
    where the option decided (``decision_data``), about one option in five on Craft. The
    rollout then runs every option's actor alone, and the critics run here on the
    decisions, grouped by option (``smjax.agents.grouped``)."""
    if config.torso != "mlp" or config.shared_torso:
        return None
    block = config.option_block

    def option_values(states, obs: jax.Array, decision: jax.Array) -> jax.Array:
        T, B, O = decision.shape
        mine = decision.reshape(T * B, O).T                          # [O, T*B]
        order = jax.vmap(decisions_first)(mine)                      # each option's decisions first
        counts = mine.sum(1).astype(jnp.int32)
        table = obs.reshape((T * B,) + obs.shape[2:])
        network = network_for(num_actions_of(states.params))

        def block_values(own, o, j, valid):
            rows = order[o, jnp.minimum(j, T * B - 1)]
            return network.apply(own, flatten_obs(table[rows]))[1]

        per_step = blocks_per_step(config.option_blocks_per_step, T * B, block, O)
        ranked = grouped_rows(block_values, states.params, counts, block, T * B, per_step)
        rank = jnp.maximum(jnp.cumsum(mine, axis=1) - 1, 0)          # a decision's place in order
        values = jnp.take_along_axis(ranked, rank, axis=1)
        return jnp.where(mine, values, 0.0).T.reshape(T, B, O)

    return option_values
