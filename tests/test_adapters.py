"""from_gymnax: the smjax protocol over gymnax environments (skipped without gymnax)."""
from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

gymnax = pytest.importorskip(
    "gymnax", reason="gymnax is an optional peer dependency: pip install 'smjax[peers]'")

from smjax.core import spaces  # noqa: E402
from smjax.core.adapters import convert_space, from_gymnax  # noqa: E402

CARTPOLE = from_gymnax(*gymnax.make("CartPole-v1"))
BREAKOUT = from_gymnax(*gymnax.make("Breakout-MinAtar"))


def _gymnax_step(genv, key, state, action, params):
    """gymnax's auto-resetting step as (obs, state, reward, done) for either API generation."""
    out = genv.step(key, state, action, params)
    if len(out) == 6:
        obs, state, reward, terminated, truncated, _ = out
        return obs, state, reward, jnp.logical_or(terminated, truncated)
    obs, state, reward, done, _ = out
    return obs, state, reward, done


def test_spaces_convert():
    env, params = CARTPOLE
    assert isinstance(env.action_space(params), spaces.Discrete)
    assert env.action_space(params).n == 2
    assert env.observation_space(params).shape == (4,)
    benv, bparams = BREAKOUT
    assert benv.action_space(bparams).n == 3
    assert benv.observation_space(bparams).shape == (10, 10, 4)


def test_unsupported_space_and_bad_inputs_raise():
    class Odd:
        pass

    with pytest.raises(ValueError, match="supported spaces: Discrete, Box"):
        convert_space(Odd())
    with pytest.raises(ValueError, match="has no reset_env"):
        from_gymnax(object(), None)
    with pytest.raises(KeyError, match="valid ids"):
        from_gymnax("NoSuchEnv-v0")


def test_from_id_uses_default_params():
    env, params = from_gymnax("CartPole-v1")
    assert params.max_steps_in_episode == 500
    assert env.name.startswith("gymnax/")


@pytest.mark.parametrize("pair", [CARTPOLE, BREAKOUT], ids=["cartpole", "breakout"])
def test_reset_step_shapes_dtypes_jit_vmap(pair):
    env, params = pair
    batch = 5
    keys = jax.random.split(jax.random.PRNGKey(0), batch)
    obs, state = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    chex.assert_shape(obs, (batch,) + env.observation_space(params).shape)
    actions = jnp.zeros((batch,), jnp.int32)
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    obs, state, reward, terminated, truncated, info = step(keys, state, actions, params)
    chex.assert_shape([reward, terminated, truncated], (batch,))
    assert reward.dtype == jnp.float32 and terminated.dtype == jnp.bool_ and truncated.dtype == jnp.bool_
    chex.assert_tree_all_finite((obs, reward))
    assert "final_observation" in info


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), always=st.sampled_from([None, 0, 1]))
def test_auto_reset_step_matches_gymnax_step(seed, always):
    """Same key => the adapter's auto-resetting step equals gymnax's own, step for step.

    (Both split the key into step/reset halves the same way.) Constant actions end
    CartPole episodes within ~10 steps, so resets are exercised.
    """
    env, params = CARTPOLE
    genv = env.gymnax_env

    def run(key):
        key, key_reset = jax.random.split(key)
        obs, state = env.reset(key_reset, params)
        g_obs, g_state = genv.reset(key_reset, params)

        def body(carry, step_key):
            state, g_state = carry
            key_act, key_step = jax.random.split(step_key)
            action = (jax.random.randint(key_act, (), 0, 2) if always is None
                      else jnp.asarray(always, jnp.int32))
            obs, state, reward, term, trunc, _ = env.step(key_step, state, action, params)
            g_obs, g_state, g_reward, g_done = _gymnax_step(genv, key_step, g_state, action, params)
            return (state, g_state), (obs, reward, term | trunc, g_obs, g_reward, g_done)

        _, out = jax.lax.scan(body, (state, g_state), jax.random.split(key, 60))
        return out

    obs, reward, done, g_obs, g_reward, g_done = jax.jit(run)(jax.random.PRNGKey(seed))
    np.testing.assert_array_equal(obs, g_obs)
    np.testing.assert_array_equal(reward, g_reward)
    np.testing.assert_array_equal(done, g_done)
    if always is not None:
        assert done.any(), "a constant action should end a CartPole episode within 60 steps"


def test_step_env_does_not_reset_and_reports_termination():
    env, params = CARTPOLE
    obs, state = env.reset(jax.random.PRNGKey(1), params)
    step_env = jax.jit(env.step_env)
    for t in range(100):
        obs, next_state, reward, terminated, truncated, _ = step_env(
            jax.random.PRNGKey(t), state, jnp.int32(1), params)
        if bool(terminated):
            break
        state = next_state
    assert bool(terminated) and not bool(truncated)
    # No auto-reset: the terminal state is the continuation of the previous one
    # (the pole is past its limit), not a fresh start near zero.
    assert abs(float(next_state.theta)) > params.theta_threshold_radians or \
        abs(float(next_state.x)) > params.x_threshold
    assert int(next_state.time) == t + 1


@settings(max_examples=8, deadline=None)
@given(limit=st.integers(1, 8), seed=st.integers(0, 1000))
def test_time_limit_is_truncation_not_termination(limit, seed):
    """Alternating actions keep the pole up for > 8 steps: the episode ends by the limit."""
    env, params = CARTPOLE
    params = params.replace(max_steps_in_episode=limit)
    _, state = env.reset(jax.random.PRNGKey(seed), params)
    step_env = jax.jit(env.step_env)
    for t in range(limit):
        _, state, _, terminated, truncated, _ = step_env(
            jax.random.PRNGKey(t), state, jnp.int32(t % 2), params)
        assert not bool(terminated)
        assert bool(truncated) == (t == limit - 1)


def test_flat_ppo_trains_on_adapted_cartpole():
    from smjax.agents import make_agent
    from smjax.agents.flat_train import FlatTrainConfig, make_train

    env, params = CARTPOLE
    agent = make_agent("ppo", learning_rate=2.5e-3, update_epochs=2, num_minibatches=2)
    config = FlatTrainConfig(num_envs=4, num_steps=32, num_updates=3)
    _, metrics = jax.jit(make_train(config, env, params, agent))(jax.random.PRNGKey(0))
    assert metrics["episodes"].shape == (3,)
    assert int(metrics["episodes"].sum()) > 0  # 384 random-ish CartPole steps end episodes
    chex.assert_tree_all_finite(metrics["total_loss"])


class _GymnaxOneStyleCartPole:
    """CartPole in gymnax >= 1.0's shape: step_env's flag is termination only and the
    time limit is a separate ``is_truncated`` (built from gymnax 0.0.x's CartPole)."""

    def __init__(self):
        self.inner, self.default_params = gymnax.make("CartPole-v1")

    def reset_env(self, key, params):
        return self.inner.reset_env(key, params)

    def step_env(self, key, state, action, params):
        obs, state, reward, done, info = self.inner.step_env(key, state, action, params)
        fell = jnp.logical_or(jnp.abs(state.x) > params.x_threshold,
                              jnp.abs(state.theta) > params.theta_threshold_radians)
        return obs, state, reward, fell, info

    def is_truncated(self, state, params):
        return state.time >= params.max_steps_in_episode

    def action_space(self, params):
        return self.inner.action_space(params)

    def observation_space(self, params):
        return self.inner.observation_space(params)


def test_gymnax_one_api_uses_is_truncated():
    genv = _GymnaxOneStyleCartPole()
    env, params = from_gymnax(genv)
    params = params.replace(max_steps_in_episode=3)
    _, state = env.reset(jax.random.PRNGKey(0), params)
    flags = []
    for t in range(3):
        _, state, _, terminated, truncated, _ = env.step_env(
            jax.random.PRNGKey(t), state, jnp.int32(t % 2), params)
        flags.append((bool(terminated), bool(truncated)))
    assert flags == [(False, False), (False, False), (False, True)]
    # Falling over is a termination, and then never also a truncation.
    params = params.replace(max_steps_in_episode=500)
    _, state = env.reset(jax.random.PRNGKey(0), params)
    for t in range(100):
        _, state, _, terminated, truncated, _ = env.step_env(jax.random.PRNGKey(t), state, jnp.int32(1), params)
        if bool(terminated):
            break
    assert bool(terminated) and not bool(truncated)


@pytest.mark.slow
def test_peer_scripts_smoke(tmp_path):
    """The peer benchmark scripts run end to end at tiny sizes and write their JSON."""
    import importlib.util
    import json
    import os
    import sys

    pytest.importorskip("rejax", reason="rejax is an optional peer dependency")
    here = os.path.join(os.path.dirname(__file__), "..", "benchmarks", "peers")
    sys.path.insert(0, os.path.abspath(here))
    try:
        spec = importlib.util.spec_from_file_location("ppo_vs_rejax", os.path.join(here, "ppo_vs_rejax.py"))
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        out = tmp_path / "ppo.json"
        summary = module.main(["--envs", "CartPole-v1", "--num-envs", "4", "--num-steps", "16",
                               "--total-steps", "128", "--minibatches", "2", "--epochs", "1",
                               "--repeats", "1", "--eval-episodes", "4", "--eval-max-steps", "50",
                               "--json", str(out)])
        row = json.loads(out.read_text())["results"][0]
        assert row["ratio_smjax_over_rejax"] > 0 and row["smjax"]["env_steps"] == 128
        assert summary["versions"]["rejax"] != "missing"
    finally:
        sys.path.remove(os.path.abspath(here))


# ---- smjax's trainer on a gymnax task: flat needs no hierarchy; success may be unbounded --
def _cartpole_run(method="flat", **kw):
    from smjax.train import TrainConfig
    from smjax.train.run import run

    cfg = TrainConfig(method=method, num_envs=8, rollout_ticks=16, updates_per_chunk=2,
                      max_episodes_per_level=40, success_window=8, eval_envs=8,
                      checkpoint_every=0.0, threshold=0.8)
    env, params = from_gymnax(*gymnax.make("CartPole-v1"))
    return run((env, params), cfg, [0], progress=False, **kw)


def test_flat_training_needs_no_declared_hierarchy():
    res = _cartpole_run()
    assert res["config"]["hierarchy_used"] == "primitives:flattened"
    assert [lv["template"] for lv in res["levels"]] == ["task"]


def test_an_unbounded_success_never_reaches_a_threshold():
    """CartPole's success is its return (tens): compared with 0.8 it would "reach" at once.
    The run says so, spends the level's budget, and reports no episodes to threshold."""
    with pytest.warns(UserWarning, match=r"not known to lie in \[0, 1\]"):
        res = _cartpole_run()
    assert res["success_unbounded"] is True
    assert res["levels"][0]["reached"] == [False]
    assert res["episodes_to_threshold"] == [None]
    assert res["levels"][0]["episodes"][0] >= 40  # the whole budget


def test_the_top_down_method_still_needs_a_hierarchy():
    with pytest.raises(ValueError, match="declares no hierarchies"):
        _cartpole_run(method="top-down")
