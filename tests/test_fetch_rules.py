"""Fetch & Stack rules without physics: registry, model, sampling, reward, observation."""
import functools
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as hs

import smjax
from smjax.envs.fetch import types as st
from smjax.envs.fetch.model import BLOCK_REST_Z, GRIPPER_START, build_model
from smjax.envs.fetch.dynamics import reward, score
from smjax.envs.fetch.observation import observation
from smjax.envs.fetch.reset import sample_blocks, sample_goals
from smjax.envs.fetch.types import FetchConfig


@pytest.fixture(scope="module")
def env3():
    env, params = smjax.make("fetch/stack3")
    _, state = jax.jit(env.reset_env)(jax.random.PRNGKey(0), params)
    return env, params, state


_REWARD = jax.jit(reward)


@functools.lru_cache(maxsize=None)
def _sampler(n):
    config = FetchConfig(num_blocks=n)

    @jax.jit
    def sample(key, params):
        kg, kb = jax.random.split(key)
        goals = sample_goals(kg, params, n)
        return goals, sample_blocks(kb, goals[0, :2], params, config)

    return sample


def test_registry_names_and_overrides():
    names = smjax.registry()
    for n in range(1, 7):
        assert f"fetch/stack{n}" in names
    env, params = smjax.make("fetch/stack3", num_blocks=5)
    assert env.num_blocks == 5 and int(params.max_steps) == 250
    env4, params4 = smjax.make("fetch/stack4")
    assert env4.observation_space(params4).shape == (70,) and int(params4.max_steps) == 200
    assert env4.action_space(params4).shape == (4,)


def test_bad_overrides_raise_clear_errors():
    with pytest.raises(ValueError, match="num_blocks"):
        smjax.make("fetch/stack3", num_blocks=7)
    with pytest.raises(TypeError, match="valid overrides"):
        smjax.make("fetch/stack3", blocks=2)
    with pytest.raises(ValueError, match="substeps"):
        smjax.make("fetch/stack3", substeps=0)


@pytest.mark.parametrize("n", [1, 3, 4, 6])
def test_model_builds_with_expected_sizes(n):
    m = build_model(n)
    assert m.nq == 9 + 7 * n and m.nv == 8 + 6 * n and m.nu == 2 and m.nmocap == 1
    # explicit pairs only: table, block-block, two fingers per block
    assert m.npair == n + n * (n - 1) // 2 + 2 * n
    assert abs(m.opt.timestep * 8 - 0.04) < 1e-9


@settings(max_examples=25, deadline=None)
@given(seed=hs.integers(0, 2**31 - 1), n=hs.integers(1, 4))
def test_goal_and_block_sampling_constraints(seed, n):
    params = st.FetchParams()
    goals, blocks = (np.asarray(x) for x in _sampler(n)(jax.random.PRNGKey(seed), params))
    start = np.asarray(GRIPPER_START[:2])
    assert np.all(np.abs(goals[0, :2] - start) <= 0.15 + 1e-6)
    np.testing.assert_allclose(goals[0, 2], BLOCK_REST_Z, atol=1e-6)
    np.testing.assert_allclose(goals[:, :2], np.broadcast_to(goals[0, :2], (n, 2)), atol=1e-6)
    np.testing.assert_allclose(np.diff(goals[:, 2]), 0.05, atol=1e-6)
    assert np.all(np.abs(blocks - start) <= 0.15 + 1e-6)
    assert np.all(np.linalg.norm(blocks - start, axis=-1) >= 0.1 - 1e-6)
    assert np.all(np.linalg.norm(blocks - goals[0, :2], axis=-1) >= 0.05)
    for i in range(n):
        for j in range(i):
            assert np.max(np.abs(blocks[i] - blocks[j])) >= 0.055 - 1e-6


def _with_positions(env, state, grip, blocks):
    qpos = state.data.qpos.at[0:3].set(jnp.asarray(grip, jnp.float32))
    for i, b in enumerate(blocks):
        qpos = qpos.at[9 + 7 * i: 12 + 7 * i].set(jnp.asarray(b, jnp.float32))
    return state.replace(data=state.data.replace(qpos=qpos))


@settings(max_examples=30, deadline=None)
@given(offsets=hs.lists(hs.floats(0.0, 0.1), min_size=3, max_size=3),
       grip_height=hs.floats(0.0, 0.3))
@example(offsets=[0.0, 0.0, 0.04], grip_height=0.0)  # a float64 rule got this one wrong
def test_reward_and_success_rules(env3, offsets, grip_height):
    env, params, state = env3
    goals = np.asarray(state.goals)
    blocks = goals + np.stack([np.asarray(offsets), np.zeros(3), np.zeros(3)], axis=-1)
    grip = goals[-1] + np.array([0.0, 0.0, grip_height])
    s = _with_positions(env, state, grip, blocks)
    r = float(_REWARD(s, params))
    # the rule in the state's float32, as the environment computes it: at an offset of
    # exactly 0.04, float32(1.3 + 0.04) - float32(1.3) lies below float32(0.04) (placed)
    goals32, blocks32, grip32 = (np.asarray(x, np.float32) for x in (goals, blocks, grip))
    placed = np.linalg.norm(blocks32 - goals32, axis=-1) < np.float32(0.04)
    grip_far = np.min(np.linalg.norm(goals32 - grip32, axis=-1)) > np.float32(0.08)
    expected = -float(np.sum(~placed)) + (1.0 if placed.all() and grip_far else 0.0)
    assert r == expected
    assert float(score(jnp.asarray(r), 3)) == pytest.approx((min(0.0, expected) + 3) / 3)


def test_observation_layout(env3):
    env, params, state = env3
    grip = np.array([1.30, 0.70, 0.50])
    blocks = np.array([[1.2, 0.6, 0.425], [1.25, 0.8, 0.425], [1.4, 0.9, 0.425]])
    s = _with_positions(env, state, grip, blocks)
    obs = np.asarray(observation(s, env.config))
    chex.assert_shape(obs, (55,))
    np.testing.assert_allclose(obs[0:3], grip, atol=1e-6)
    np.testing.assert_allclose(obs[3:5], [0.05, 0.05], atol=1e-6)
    for i in range(3):
        row = obs[10 + 15 * i: 25 + 15 * i]
        np.testing.assert_allclose(row[0:3], blocks[i], atol=1e-6)
        np.testing.assert_allclose(row[3:6], blocks[i] - grip, atol=1e-6)
        np.testing.assert_allclose(row[6:9], 0.0, atol=1e-6)  # identity orientation
    goals_env = smjax.make("fetch/stack3", obs_include_goals=True)[0]
    chex.assert_shape(observation(s, goals_env.config), (64,))


def test_euler_of_known_rotation():
    half = np.pi / 8  # 45 degrees about z
    quat = jnp.asarray([np.cos(half), 0.0, 0.0, np.sin(half)])
    np.testing.assert_allclose(st.quat_to_euler(quat), [0.0, 0.0, np.pi / 4], atol=1e-6)
    rot = np.asarray(st.quat_to_mat(quat))
    np.testing.assert_allclose(rot @ np.array([1.0, 0, 0]), [np.cos(np.pi / 4), np.sin(np.pi / 4), 0],
                               atol=1e-6)


def test_diverged_physics_terminates_with_a_finite_observation(env3):
    env, params, state = env3
    step = jax.jit(env.step_env)
    bad = state.replace(data=state.data.replace(qvel=state.data.qvel.at[-1].set(jnp.nan)))
    obs, _, r, terminated, _, info = step(jax.random.PRNGKey(1), bad, jnp.zeros(4), params)
    assert bool(terminated) and bool(info["physics_diverged"]) and float(r) == 0.0
    assert float(info["success"]) == 0.0 and float(info["score"]) == 0.0  # not "all placed"
    assert np.isfinite(np.asarray(obs)).all()
    _, _, _, terminated, _, info = step(jax.random.PRNGKey(1), state, jnp.zeros(4), params)
    assert not bool(terminated) and not bool(info["physics_diverged"])
