"""DQN: replay insertion, SMDP targets against a Python reference, target network, learning."""
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
from smjax.agents.base import Transition
from smjax.agents.dqn import smdp_td_targets
from smjax.agents.flat_train import FlatTrainConfig, make_train
from test_agents_smdp import reference_transitions

NUM_ACTIONS = 4
OBS_DIM = 3
FAST = dict(learning_starts=64, epsilon_decay_steps=2000, target_update_period=20,
            gradient_steps_per_update=8, learning_rate=1e-3, buffer_capacity=4096)


def random_traj(seed: int, num_ticks: int = 7, num_envs: int = 3) -> Transition:
    rng = np.random.default_rng(seed)
    shape = (num_ticks, num_envs)
    mask = rng.random(shape + (NUM_ACTIONS,)) < 0.6
    mask[..., 0] |= ~mask.any(-1)
    traj = Transition(
        obs=rng.integers(0, 9, shape + (OBS_DIM,)).astype(np.uint8),
        action=np.argmax(mask * rng.random(mask.shape), -1).astype(np.int32),  # an allowed one
        action_mask=mask,
        log_prob=(-1.0 - 0.3 * rng.random(shape)).astype(np.float32),
        value=rng.normal(size=shape).astype(np.float32),
        decision=rng.random(shape) < 0.6,
        reward=rng.normal(size=shape).astype(np.float32),
        discount=rng.choice([0.9, 0.9, 0.9**7], size=shape).astype(np.float32),
        done=rng.random(shape) < 0.15,
    )
    return traj


def reference_rows(traj):
    """Python SMDP transitions of the complete decisions in insertion order (tick-major,
    then environment); decisions pending at the rollout end are not stored."""
    rows = reference_transitions(traj.reward, traj.discount, traj.done, traj.decision,
                                 traj.obs, traj.action_mask)
    return [(traj.obs[t, b], traj.action[t, b]) + row[2:] for row in rows for t, b in [row[:2]]
            if row[-1]]


def _init(agent, seed=0):
    return agent.init(jax.random.PRNGKey(seed), jnp.zeros((OBS_DIM,), jnp.uint8), NUM_ACTIONS)


def _fill_only(capacity):
    agent = make_agent("dqn", buffer_capacity=capacity, learning_starts=10**6)
    return agent, jax.jit(agent.update)


# compiled once per capacity and shared by all hypothesis examples
_FILL_ONLY = {capacity: _fill_only(capacity) for capacity in (5, 64)}


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), capacity=st.sampled_from([5, 64]))
def test_buffer_holds_smdp_transitions_of_decisions_only(seed, capacity):
    agent, update = _FILL_ONLY[capacity]
    traj = random_traj(seed)
    state, metrics = update(_init(agent), traj, jax.random.PRNGKey(0))
    rows = reference_rows(traj)
    buf = jax.tree.map(np.asarray, state.buffer)
    assert int(buf.size) == min(len(rows), capacity)
    assert int(buf.insert_pos) == len(rows) % capacity
    assert int(state.grad_steps) == 0  # below learning_starts: no step
    kept = list(enumerate(rows))[-capacity:]  # a full buffer keeps the newest rows
    for rank, (obs, action, reward, discount, terminal, next_obs, next_mask, _) in kept:
        slot = rank % capacity
        np.testing.assert_array_equal(buf.obs[slot], obs)
        assert buf.action[slot] == action
        np.testing.assert_allclose(buf.reward[slot], reward, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(buf.discount[slot], discount, rtol=1e-5)
        assert buf.terminal[slot] == terminal
        if not terminal:
            np.testing.assert_array_equal(buf.next_obs[slot], next_obs)
            np.testing.assert_array_equal(buf.next_mask[slot], next_mask)


def test_pending_decisions_are_not_stored():
    traj = random_traj(3)
    agent = make_agent("dqn", learning_starts=10**6)
    state, metrics = agent.update(_init(agent), traj, jax.random.PRNGKey(0))
    assert int(state.buffer.size) == len(reference_rows(traj)) < int(np.sum(traj.decision))
    assert int(metrics["decisions"]) == int(state.buffer.size)


@pytest.mark.parametrize("double_dqn", [False, True])
def test_smdp_targets_match_python_reference(double_dqn):
    agent = make_agent("dqn", learning_starts=10**6, double_dqn=double_dqn)
    traj = random_traj(11, num_ticks=9)
    state, _ = agent.update(_init(agent), traj, jax.random.PRNGKey(0))
    online, target = _init(agent, 1).params, _init(agent, 2).params  # deliberately different
    buf = jax.tree.map(np.asarray, state.buffer)
    n = int(buf.size)
    q_online = np.asarray(agent.policy_logits(online, buf.next_obs[:n]))
    q_target = np.asarray(agent.policy_logits(target, buf.next_obs[:n]))
    got = smdp_td_targets(q_online, q_target, buf.reward[:n], buf.discount[:n], buf.terminal[:n],
                          buf.next_mask[:n], double_dqn)
    for i, row in enumerate(reference_rows(traj)):
        _, _, reward, discount, terminal, _, next_mask, _ = row
        if terminal:
            expected = reward
        else:
            allowed = np.flatnonzero(next_mask)
            chooser = q_online if double_dqn else q_target
            best = allowed[np.argmax(chooser[i, allowed])]
            expected = reward + discount * q_target[i, best]
        np.testing.assert_allclose(got[i], expected, rtol=1e-5, atol=1e-5)


def test_hard_and_polyak_target_updates():
    traj = random_traj(5, num_ticks=12, num_envs=4)
    agent = make_agent("dqn", learning_starts=1, gradient_steps_per_update=2, target_update_period=3)
    s0 = _init(agent)
    s1, _ = agent.update(s0, traj, jax.random.PRNGKey(1))
    s2, _ = agent.update(s1, traj, jax.random.PRNGKey(2))
    leaves = lambda t: jax.tree.leaves(t)  # noqa: E731
    assert int(s1.grad_steps) == 2 and int(s2.grad_steps) == 4
    assert all(np.array_equal(a, b) for a, b in zip(leaves(s1.target_params), leaves(s0.params)))
    assert not all(np.array_equal(a, b) for a, b in zip(leaves(s2.target_params), leaves(s0.params)))
    assert not all(np.array_equal(a, b) for a, b in zip(leaves(s2.target_params), leaves(s2.params)))

    agent = make_agent("dqn", learning_starts=1, gradient_steps_per_update=1,
                       target_update_period=1, tau=0.25)
    s0 = _init(agent)
    s1, _ = agent.update(s0, traj, jax.random.PRNGKey(1))
    for tgt, new, old in zip(leaves(s1.target_params), leaves(s1.params), leaves(s0.params)):
        np.testing.assert_allclose(tgt, 0.25 * new + 0.75 * old, rtol=1e-5, atol=1e-7)


def test_epsilon_schedule_is_linear_in_decisions():
    agent = make_agent("dqn", epsilon_start=1.0, epsilon_end=0.1, epsilon_decay_steps=40,
                       learning_starts=10**6)
    traj = random_traj(0)
    decisions = len(reference_rows(traj))  # complete ones; a pending one counts when it completes
    state, metrics = agent.update(_init(agent), traj, jax.random.PRNGKey(0))
    np.testing.assert_allclose(metrics["epsilon"], 1.0 - 0.9 * min(decisions / 40, 1.0), rtol=1e-5)


def test_dqn_learns_corridor_and_is_deterministic():
    env = Corridor(6)
    config = FlatTrainConfig(num_envs=8, num_steps=16, num_updates=60)
    train = jax.jit(make_train(config, env, env.default_params, make_agent("dqn", **FAST)))
    state, metrics = train(jax.random.PRNGKey(0))
    returns = np.asarray(metrics["mean_episode_return"])
    assert np.nanmean(returns[:3]) < 0.4          # epsilon ~1: near random
    assert np.nanmean(returns[-10:]) > 0.6         # learned (4 other seeds: 0.69 .. 0.94)
    chex.assert_tree_all_finite({k: v for k, v in metrics.items() if "episode" not in k})
    chex.assert_shape(metrics["loss"], (60,))
    state2, metrics2 = train(jax.random.PRNGKey(0))
    chex.assert_trees_all_equal(state.params, state2.params)


def test_dqn_prefers_the_option_with_the_best_smdp_value():
    train = jax.jit(make_option_driver_train(make_agent("dqn", **FAST), 8, 32, 50))
    state, metrics = train(jax.random.PRNGKey(0))
    assert int(metrics["masked_violations"].sum()) == 0
    q = make_agent("dqn").policy_logits(state.params, option_observation(jnp.arange(EPISODE_TICKS - 2)))
    assert np.all(np.argmax(q, -1) == 0)
    assert float(metrics["chose_option0"][-5:].mean()) > 0.85


def test_swept_hyper_parameters_are_read_from_the_state():
    """A state whose ``hp`` holds other values trains exactly as a config with those values
    (a sweep puts each point's values there and compiles once)."""
    swept = dict(epsilon_end=0.2, epsilon_decay_steps=30, target_update_period=3, tau=0.5,
                 reward_scale=0.25, learning_rate=3e-3)
    common = dict(learning_starts=1, gradient_steps_per_update=4)
    direct = make_agent("dqn", **common, **swept)
    other = make_agent("dqn", **common)  # the defaults, overridden through state.hp only
    s_direct, m_direct = direct.update(_init(direct), random_traj(3, 12, 4), jax.random.PRNGKey(1))
    s_other = _init(other)
    s_other = s_other.replace(hp={k: jnp.asarray(swept.get(k, v), jnp.float32)
                                  for k, v in s_other.hp.items()})
    assert set(s_other.hp) == set(swept)
    s_other, m_other = other.update(s_other, random_traj(3, 12, 4), jax.random.PRNGKey(1))
    for a, b in zip(jax.tree.leaves((s_direct.params, s_direct.target_params, s_direct.buffer)),
                    jax.tree.leaves((s_other.params, s_other.target_params, s_other.buffer))):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(m_direct["epsilon"], m_other["epsilon"])
