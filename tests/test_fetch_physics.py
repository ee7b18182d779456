"""Fetch & Stack physics fidelity and env-step properties (MJX on CPU, 2 blocks, tiny batches)."""
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from smjax.envs.fetch import types as st
from smjax.envs.fetch.model import BLOCK_REST_Z


@pytest.fixture(scope="module")
def fetch2():
    env, params = smjax.make("fetch/stack2")
    reset = jax.jit(env.reset_env)
    step = jax.jit(env.step_env)
    _, state = reset(jax.random.PRNGKey(0), params)
    return env, params, reset, step, state


def _pose(state, grip=None, blocks=None, fingers=None):
    data = state.data
    qpos, mocap, ctrl = data.qpos, data.mocap_pos, data.ctrl
    if grip is not None:
        grip = jnp.asarray(grip, jnp.float32)
        qpos = qpos.at[0:3].set(grip)
        mocap = grip[None, :]
    if blocks is not None:
        for i, b in enumerate(blocks):
            qpos = qpos.at[9 + 7 * i: 12 + 7 * i].set(jnp.asarray(b, jnp.float32))
    if fingers is not None:
        qpos = qpos.at[7:9].set(fingers)
        ctrl = jnp.full((2,), fingers, jnp.float32)
    return state.replace(data=data.replace(qpos=qpos, qvel=jnp.zeros_like(data.qvel),
                                           mocap_pos=mocap, ctrl=ctrl))


def _run(step, params, state, action, n):
    action = jnp.asarray(action, jnp.float32)
    key = jax.random.PRNGKey(0)
    for _ in range(n):
        _, state, *_ = step(key, state, action, params)
    return state


def test_full_x_action_moves_gripper_5cm(fetch2):
    env, params, _, step, state = fetch2
    x0 = float(st.gripper_pos(state)[0])
    obs, s1, reward, terminated, truncated, info = step(
        jax.random.PRNGKey(0), state, jnp.asarray([1.0, 0, 0, 0]), params)
    chex.assert_shape(obs, (40,))
    chex.assert_tree_all_finite(obs)
    assert not bool(terminated) and not bool(truncated)
    assert float(s1.data.mocap_pos[0, 0]) - x0 == pytest.approx(0.05, abs=1e-6)
    s2 = _run(step, params, s1, [0, 0, 0, 0], 2)
    moved = np.asarray(st.gripper_pos(s2)) - np.asarray(st.gripper_pos(state))
    assert moved[0] == pytest.approx(0.05, abs=0.005)
    assert abs(moved[1]) < 0.003 and abs(moved[2]) < 0.003


def test_workspace_clamps_the_target(fetch2):
    env, params, _, step, state = fetch2
    s = _run(step, params, state, [0, 0, -1, 0], 6)
    assert float(s.data.mocap_pos[0, 2]) == pytest.approx(BLOCK_REST_Z, abs=1e-6)


def test_fingers_close_and_open(fetch2):
    env, params, _, step, state = fetch2
    s = _pose(state, grip=[1.34, 0.75, 0.6])  # in the air, nothing between the fingers
    closed = _run(step, params, s, [0, 0, 0, -1], 8)
    assert np.all(np.asarray(st.finger_qpos(closed)) < 0.004)
    held = _run(step, params, closed, [0, 0, 0, 0], 2)  # 0 keeps the target
    assert np.all(np.asarray(st.finger_qpos(held)) < 0.004)
    opened = _run(step, params, held, [0, 0, 0, 1], 8)
    assert np.all(np.asarray(st.finger_qpos(opened)) > 0.046)


def test_dropped_block_rests_on_table(fetch2):
    env, params, _, step, state = fetch2
    s = _pose(state, grip=[1.34, 0.75, 0.7], blocks=[[1.25, 0.65, 0.55], [1.45, 0.85, 0.425]])
    s = _run(step, params, s, [0, 0, 0, 0], 25)  # one second
    block = np.asarray(st.block_pos(s))
    assert block[0, 2] == pytest.approx(BLOCK_REST_Z, abs=0.003)
    np.testing.assert_allclose(block[0, :2], [1.25, 0.65], atol=0.01)
    assert np.max(np.abs(np.asarray(st.block_linvel(s)))) < 0.02


def test_block_on_block_stays(fetch2):
    env, params, _, step, state = fetch2
    top = [1.30, 0.70, BLOCK_REST_Z + 0.05]
    s = _pose(state, grip=[1.34, 0.85, 0.7], blocks=[[1.30, 0.70, BLOCK_REST_Z], top])
    s = _run(step, params, s, [0, 0, 0, 0], 25)
    np.testing.assert_allclose(np.asarray(st.block_pos(s))[1], top, atol=0.004)


def test_closed_gripper_lifts_block_without_slipping(fetch2):
    env, params, _, step, state = fetch2
    block = [1.30, 0.70, BLOCK_REST_Z]
    s = _pose(state, grip=block, blocks=[block, [1.45, 0.85, BLOCK_REST_Z]], fingers=0.05)
    s = _run(step, params, s, [0, 0, 0, -1], 6)  # close
    gap = float(jnp.sum(st.finger_qpos(s)))
    assert 0.04 < gap < 0.056  # stopped by the 5 cm block
    s = _run(step, params, s, [0, 0, 1, -1], 4)  # lift 20 cm
    s = _run(step, params, s, [1, 0, 0, 0], 2)  # carry sideways, keeping the grip
    s = _run(step, params, s, [0, 0, 0, 0], 10)  # hold
    grip, blk = np.asarray(st.gripper_pos(s)), np.asarray(st.block_pos(s))[0]
    assert grip[2] > BLOCK_REST_Z + 0.19
    np.testing.assert_allclose(blk, grip, atol=0.012)


def test_determinism_and_vmap_matches_single(fetch2):
    env, params, reset, step, _ = fetch2
    keys = jax.random.split(jax.random.PRNGKey(7), 2)
    actions = jax.random.uniform(jax.random.PRNGKey(8), (2, 3, 4), minval=-1, maxval=1)

    def rollout(key, acts):
        obs0, s = env.reset_env(key, params)

        def tick(s, a):
            obs, s, *_ = env.step_env(key, s, a, params)
            return s, obs

        _, obs = jax.lax.scan(tick, s, acts)
        return jnp.concatenate([obs0[None], obs])

    batched = jax.jit(jax.vmap(rollout))(keys, actions)

    def single(key, acts):  # one environment, step by step (the fixture's compiled functions)
        obs0, s = reset(key, params)
        obs = [obs0]
        for a in acts:
            o, s, *_ = step(key, s, a, params)
            obs.append(o)
        return jnp.stack(obs)

    first = single(keys[0], actions[0])
    again = single(keys[0], actions[0])
    np.testing.assert_array_equal(np.asarray(first), np.asarray(again))
    for b in range(2):
        np.testing.assert_allclose(np.asarray(batched[b]), np.asarray(single(keys[b], actions[b])),
                                   atol=2e-4)


def test_truncation_and_auto_reset(fetch2):
    env, params, _, step, state = fetch2
    short = params.replace(max_steps=jnp.asarray(2, jnp.int32))
    key = jax.random.PRNGKey(1)
    _, s1, _, _, trunc1, _ = step(key, state, jnp.zeros(4), short)
    _, s2, _, term2, trunc2, info = step(key, s1, jnp.zeros(4), short)
    assert not bool(trunc1) and bool(trunc2) and not bool(term2)
    assert set(info) >= {"score", "is_success", "placed"}
