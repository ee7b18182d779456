"""DQN's update for a learner per option at once: ``Agent.update_options``.

The result is that of ``update`` run once per option with ``jax.random.split(key, O)``:
the same rows stored in each option's buffer at the same places, then the same gradient
steps. The steps do not follow the decisions (each option takes
``gradient_steps_per_update`` steps on ``batch_size`` rows sampled from its own buffer,
whatever the rollout held), so they run option by option as in ``update``, vmapped.
What follows the rows is storing the rollout: ``update`` option by option reads every
row's observation copied per option, and pairs each decision with the observation of
its next decision in a scan over those observations. Here the pairing runs on the
batch's row indices into its one table of observations (integers: the scan carries one
per environment, not an observation), and the observations are gathered from the table
only where the rows are written.

Why no loop over blocks of each option's decisions, as PPO's and the actor-critic's
grouped updates have: the loop would carry the buffers, and under ``vmap`` (seeds) a
loop whose trip count differs between seeds selects its whole carry on every turn, a
copy of every buffer per block (on 2 CPU cores, 2 seeds of 6 options: ~50x the time of
the write here). The gather and write here are of fixed shape.
"""
from __future__ import annotations

import jax

from smjax.agents.dqn_update import insert, rollout_items, train_steps
from smjax.agents.option_batch import OptionBatch


def make_update_options(config, step):
    """``update_options(states, batch, key)`` for DQN's ``config`` and its gradient
    ``step(state, key) -> (state, metrics)``."""

    def update_options(states, batch: OptionBatch, key: jax.Array):
        # batch.traj.obs: each row's index into batch.obs, so items["obs"] and
        # items["next_obs"] come out as indices too
        states, items, valid, decisions = jax.vmap(rollout_items)(states, batch.traj)
        items = dict(items, obs=batch.obs[items["obs"]], next_obs=batch.obs[items["next_obs"]])
        states = states.replace(buffer=jax.vmap(insert)(states.buffer, items, valid))
        keys = jax.random.split(key, decisions.shape[0])
        return jax.vmap(lambda s, k, n: train_steps(config, step, s, k, n))(
            states, keys, decisions)

    return update_options
