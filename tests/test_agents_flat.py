"""Flat PureJaxRL training: determinism, vmapped seeds, metrics, bad input."""
from __future__ import annotations

import chex
import jax
import numpy as np
import pytest

from envs_for_tests import Corridor
from smjax.agents import ALGOS, make_agent
from smjax.agents.flat_train import FlatTrainConfig, make_train
from smjax.core import spaces

CORRIDOR = Corridor(6)
SMALL = FlatTrainConfig(num_envs=4, num_steps=16, num_updates=4)
OVERRIDES = {"ppo": {}, "actor-critic": {}, "dqn": {"learning_starts": 16, "gradient_steps_per_update": 2}}


@pytest.mark.parametrize("algo", ALGOS)
def test_deterministic_and_vmapped_seeds_match_single_runs(algo):
    train = make_train(SMALL, CORRIDOR, CORRIDOR.default_params, make_agent(algo, **OVERRIDES[algo]))
    keys = jax.random.split(jax.random.PRNGKey(42), 2)
    batched_state, batched_metrics = jax.jit(jax.vmap(train))(keys)
    single = jax.jit(train)
    for i in range(2):
        state, metrics = single(keys[i])
        again, _ = single(keys[i])
        chex.assert_trees_all_equal(state.params, again.params)
        chex.assert_trees_all_close(
            jax.tree.map(lambda x: x[i], batched_state.params), state.params, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(batched_metrics["mean_episode_return"][i],
                                   metrics["mean_episode_return"], rtol=1e-5)
    first_leaf = jax.tree.leaves(batched_state.params)[0]
    assert not np.allclose(first_leaf[0], first_leaf[1])  # the seeds really differ
    for name, value in batched_metrics.items():
        chex.assert_shape(value, (2, SMALL.num_updates))
    assert int(batched_metrics["episodes"].sum()) > 0
    # every tick decides; each decision trains once, when the next tick's has been made: the
    # last tick of a rollout trains in the next one, and only the very last can stay pending
    total = SMALL.num_envs * SMALL.num_steps * SMALL.num_updates
    trained = np.asarray(batched_metrics["decisions"]).sum(-1)
    assert np.all((trained >= total - SMALL.num_envs) & (trained <= total))


def test_episode_statistics_match_the_environment():
    # an agent that always moves right finishes every episode in length - 1 = 5 steps
    agent = make_agent("ppo")
    always_right = agent._replace(
        act=lambda state, obs, mask, key: agent.act(state, obs, mask & (np.arange(3) == 1), key))
    config = FlatTrainConfig(num_envs=3, num_steps=10, num_updates=2)
    _, metrics = jax.jit(make_train(config, CORRIDOR, CORRIDOR.default_params, always_right))(
        jax.random.PRNGKey(0))
    np.testing.assert_allclose(metrics["mean_episode_return"], 1.0)
    np.testing.assert_allclose(metrics["mean_episode_length"], 5.0)
    np.testing.assert_array_equal(metrics["episodes"], 3 * 2)  # 2 episodes per env per 10 ticks


class _BoxActions(Corridor):
    def action_space(self, params=None):
        return spaces.Box(-1.0, 1.0, (2,))


def test_continuous_action_space_is_rejected():
    env = _BoxActions()
    with pytest.raises(ValueError, match="Discrete"):
        make_train(SMALL, env, env.default_params, make_agent("ppo"))
