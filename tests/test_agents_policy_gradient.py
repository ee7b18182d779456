"""PPO and the paper's actor-critic: losses over decisions only, learning, determinism."""
from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs_for_tests import EPISODE_TICKS, Corridor, make_option_driver_train, option_observation
from smjax.agents import make_agent
from smjax.agents.actor_critic import ActorCriticConfig, exploration_epsilon
from smjax.agents.flat_train import FlatTrainConfig, make_train
from smjax.agents.smdp import complete_decisions
from test_agents_dqn import random_traj

NUM_ACTIONS = 4
OBS_DIM = 3


def _init(agent, seed=0):
    return agent.init(jax.random.PRNGKey(seed), jnp.zeros((OBS_DIM,), jnp.uint8), NUM_ACTIONS)


@pytest.mark.parametrize("algo", ["ppo", "actor-critic"])
def test_non_decision_ticks_do_not_influence_the_update(algo):
    """Changing what happens on non-decision ticks before an episode's first decision
    (or the action/obs recorded there) must not change the update at all."""
    agent = make_agent(algo)
    traj = random_traj(4, num_ticks=10, num_envs=3)
    # env 0: episode ends at tick 3; ticks 4, 5 precede the next first decision at 6
    decision = traj.decision.copy()
    done = traj.done.copy()
    decision[:, 0] = [1, 0, 1, 1, 0, 0, 1, 0, 1, 0]
    done[:, 0] = [0, 0, 0, 1, 0, 0, 0, 0, 0, 0]
    reward = traj.reward.copy()
    reward[4:6, 0] = 0.0  # by contract: reward 0 before the learner's first decision
    traj = traj._replace(decision=decision, done=done, reward=reward)
    obs = traj.obs.copy()
    action = traj.action.copy()
    obs[4:6, 0] = 7
    action[4:6, 0] = (action[4:6, 0] + 1) % NUM_ACTIONS
    # fields of non-decision ticks are unspecified: even NaN and out-of-range must not matter
    not_decided = ~decision
    log_prob = np.where(not_decided, np.nan, traj.log_prob).astype(np.float32)
    value = np.where(not_decided, np.nan, traj.value).astype(np.float32)
    action = np.where(not_decided, -1, action).astype(np.int32)
    perturbed = traj._replace(obs=obs, action=action, log_prob=log_prob, value=value)
    state = _init(agent)
    key = jax.random.PRNGKey(3)
    update = jax.jit(agent.update)
    s1, m1 = update(state, traj, key)
    s2, m2 = update(state, perturbed, key)
    chex.assert_trees_all_close(s1.params, s2.params, rtol=1e-6, atol=1e-7)
    chex.assert_trees_all_close(m1, m2, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("algo", ["ppo", "actor-critic"])
def test_update_counters_and_metrics(algo):
    agent = make_agent(algo)
    traj = random_traj(8, num_ticks=9, num_envs=2)
    state, metrics = jax.jit(agent.update)(_init(agent), traj, jax.random.PRNGKey(0))
    # decisions are counted once, when they complete (a pending one counts next rollout)
    complete = complete_decisions(jnp.asarray(traj.done), jnp.asarray(traj.decision))
    assert int(state.decisions_seen) == int(complete.sum()) <= int(traj.decision.sum())
    assert int(state.updates) == 1 and int(state.grad_steps) >= 1
    for name, value in metrics.items():
        chex.assert_shape(value, ())
    chex.assert_tree_all_finite(metrics)
    assert {"policy_loss", "value_loss", "entropy", "total_loss"} <= set(metrics)


@pytest.mark.parametrize("algo", ["ppo", "actor-critic"])
def test_rollout_without_decisions_leaves_params_untouched(algo):
    agent = make_agent(algo)
    traj = random_traj(2)
    traj = traj._replace(decision=np.zeros_like(traj.decision))
    state = _init(agent)
    new_state, metrics = agent.update(state, traj, jax.random.PRNGKey(0))
    chex.assert_trees_all_equal(new_state.params, state.params)
    chex.assert_tree_all_finite(metrics)


def test_actor_critic_epsilon_follows_episodes_seen():
    config = ActorCriticConfig()
    np.testing.assert_allclose(exploration_epsilon(config, jnp.array(0)), 1.0)
    np.testing.assert_allclose(exploration_epsilon(config, jnp.array(200)), np.exp(-1.0), rtol=1e-6)
    agent = make_agent("actor-critic")
    traj = random_traj(9, num_ticks=10, num_envs=3)
    state, metrics = agent.update(_init(agent), traj, jax.random.PRNGKey(0))
    assert int(state.episodes_seen) > 0
    np.testing.assert_allclose(metrics["epsilon"], np.exp(-5e-3 * int(state.episodes_seen)), rtol=1e-6)


CORRIDOR = Corridor(6)
FLAT = FlatTrainConfig(num_envs=8, num_steps=32, num_updates=40)
# the paper's learner with a faster epsilon decay and step size, to learn in 40 updates
LEARNERS = {"ppo": {}, "actor-critic": {"epsilon_decay": 0.05, "learning_rate": 5e-3}}


@pytest.mark.parametrize("algo", list(LEARNERS))
def test_learns_corridor(algo):
    train = jax.jit(make_train(FLAT, CORRIDOR, CORRIDOR.default_params,
                               make_agent(algo, **LEARNERS[algo])))
    _, metrics = train(jax.random.PRNGKey(0))
    returns = np.asarray(metrics["mean_episode_return"])
    assert np.nanmean(returns[:3]) < 0.3       # random walk rarely reaches the end in 12 steps
    assert np.nanmean(returns[-5:]) > 0.8     # (4 other seeds: 1.0 for both learners)
    np.testing.assert_allclose(np.asarray(metrics["mean_episode_length"])[-5:], 5.0, atol=1.0)


@pytest.mark.parametrize("algo", list(LEARNERS))
def test_prefers_the_option_with_the_best_smdp_value(algo):
    agent = make_agent(algo)
    train = jax.jit(make_option_driver_train(agent, 8, 32, 60))
    state, metrics = train(jax.random.PRNGKey(0))
    assert int(metrics["masked_violations"].sum()) == 0
    logits = agent.policy_logits(state.params, option_observation(jnp.arange(EPISODE_TICKS - 2)))
    assert np.all(np.argmax(logits, -1) == 0)
    chosen = np.asarray(metrics["chose_option0"])
    assert chosen[-5:].mean() > chosen[:5].mean() + 0.1


def test_minibatches_partition_ticks_and_share_decisions_evenly():
    from smjax.agents.ppo import minibatch_indices
    decision = jnp.asarray(np.random.default_rng(0).random(37) < 0.2)
    idx, real = minibatch_indices(jax.random.PRNGKey(0), decision, 4)
    chex.assert_shape(idx, (4, 10))
    covered = np.sort(np.asarray(idx)[np.asarray(real)])
    np.testing.assert_array_equal(covered, np.arange(37))  # every tick exactly once
    per_minibatch = np.asarray(decision)[np.asarray(idx)].__and__(np.asarray(real)).sum(1)
    assert per_minibatch.sum() == int(decision.sum())
    assert per_minibatch.max() - per_minibatch.min() <= 1


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 5000), rate=st.floats(0.0, 1.0), seed=st.integers(0, 2**31 - 1))
def test_decision_order_is_a_permutation_with_the_decisions_first(n, rate, seed):
    from smjax.agents.ppo_update import decision_order
    decision = np.random.default_rng(seed).random(n) < rate
    order = np.asarray(decision_order(jax.random.PRNGKey(seed), jnp.asarray(decision)))
    np.testing.assert_array_equal(np.sort(order), np.arange(n))
    assert decision[order[: decision.sum()]].all()


def test_decision_order_is_uniform_and_keeps_its_fallback_for_long_batches():
    """Every item is as likely to come first; a batch too long for the one-key sort's
    random bits (over 2^15 items) still gives a permutation, decisions first."""
    from smjax.agents.ppo_update import decision_order
    keys = jax.random.split(jax.random.PRNGKey(0), 4000)
    first = np.asarray(jax.vmap(lambda k: decision_order(k, jnp.ones(8, bool))[0])(keys))
    counts = np.bincount(first, minlength=8)
    assert counts.min() > 4000 / 8 * 0.8 and counts.max() < 4000 / 8 * 1.2, counts
    decision = np.random.default_rng(1).random(40_000) < 0.3
    order = np.asarray(decision_order(jax.random.PRNGKey(1), jnp.asarray(decision)))
    np.testing.assert_array_equal(np.sort(order), np.arange(40_000))
    assert decision[order[: decision.sum()]].all()


def test_ppo_target_kl_stops_the_update_once_the_policy_drifts():
    """The first minibatch always steps (its parameters are the ones that gathered the data,
    KL 0); past 1.5 x target_kl every later minibatch and epoch leaves the parameters alone;
    target_kl 0 never stops."""
    from smjax.agents.networks import masked_log_softmax, take_action

    traj = random_traj(8, num_ticks=16, num_envs=4)
    key = jax.random.PRNGKey(0)
    free = make_agent("ppo", update_epochs=3, num_minibatches=2)
    state = _init(free)
    # the log-probabilities of the policy that gathered the data: the learner's own
    logits = free.policy_logits(state.params, jnp.asarray(traj.obs).reshape(-1, OBS_DIM))
    log_prob = take_action(masked_log_softmax(logits, traj.action_mask.reshape(-1, NUM_ACTIONS)),
                           jnp.asarray(traj.action).reshape(-1))
    traj = traj._replace(log_prob=np.asarray(log_prob).reshape(traj.reward.shape))
    s_free, m_free = jax.jit(free.update)(state, traj, key)
    assert int(s_free.grad_steps) == 6 and float(m_free["kl_stopped"]) == 0.0
    tight = make_agent("ppo", update_epochs=3, num_minibatches=2, target_kl=1e-12)
    s_tight, m_tight = jax.jit(tight.update)(_init(tight), traj, key)  # same params
    assert int(s_tight.grad_steps) == 1 and float(m_tight["kl_stopped"]) == 1.0
    assert not np.allclose(jax.tree.leaves(s_tight.params)[0], jax.tree.leaves(state.params)[0])
    loose = make_agent("ppo", update_epochs=3, num_minibatches=2, target_kl=1e3)
    s_loose, m_loose = jax.jit(loose.update)(_init(loose), traj, key)
    assert float(m_loose["kl_stopped"]) == 0.0
    chex.assert_trees_all_close(s_loose.params, s_free.params, rtol=1e-6, atol=1e-7)


def test_ppo_target_kl_must_not_be_negative():
    with pytest.raises(ValueError, match="target_kl"):
        make_agent("ppo", target_kl=-0.01)
