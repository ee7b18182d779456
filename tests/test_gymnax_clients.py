"""smjax environments under gymnax-API trainers (LegacyGymnaxStep): copyable, gymnax's own
spaces, ``max_steps_in_episode``, and rejax's PPO training through it (slow)."""
from __future__ import annotations

import copy

import jax
import numpy as np
import pytest

import smjax
from smjax.core import LegacyGymnaxStep
from smjax.core.adapters import gymnax_params


def _wood():
    env, params = smjax.make("craft/get_wood", observation="compact", max_steps=20)
    return LegacyGymnaxStep(env, params), params


def test_the_wrapper_copies_and_forwards():
    env, _ = _wood()
    twin = copy.deepcopy(env)  # trainers deepcopy their config, env included
    assert twin.name == "craft/get_wood" and twin.primitive_action_names == env.primitive_action_names


def test_params_carry_max_steps_in_episode_and_still_step():
    env, params = _wood()
    wrapped = env.default_params
    assert wrapped.max_steps_in_episode == 20 and wrapped.max_steps == 20  # the params given
    assert gymnax_params(params, max_steps_in_episode=7).max_steps_in_episode == 7
    key = jax.random.PRNGKey(0)
    for p in (wrapped, params):  # the wrapped params and the environment's own
        obs, state = env.reset(key, p)
        obs2, _, reward, done, info = jax.jit(env.step)(key, state, 0, p)
        assert obs2.shape == obs.shape and reward.shape == () and done.dtype == bool
        assert "truncated" in info


def test_spaces_are_gymnax_classes():
    gymnax = pytest.importorskip("gymnax", reason="gymnax is an optional peer dependency")
    env, params = _wood()
    act, obs = env.action_space(env.default_params), env.observation_space(params)
    assert isinstance(act, gymnax.environments.spaces.Discrete) and act.n == env.num_actions
    assert isinstance(obs, gymnax.environments.spaces.Box)
    assert obs.shape == env.reset(jax.random.PRNGKey(0), params)[0].shape


@pytest.mark.slow
def test_rejax_ppo_trains_on_a_craft_task():
    rejax = pytest.importorskip("rejax", reason="rejax is an optional peer dependency")
    env, _ = _wood()
    algo = rejax.PPO.create(env=env, env_params=env.default_params, num_envs=8, num_steps=16,
                            total_timesteps=8 * 16 * 3, eval_freq=8 * 16 * 3, num_epochs=1,
                            num_minibatches=2, agent_kwargs={"hidden_layer_sizes": (32,)})
    state, (lengths, returns) = jax.jit(algo.train)(jax.random.PRNGKey(0))
    assert int(state.global_step) >= 8 * 16 * 3
    returns = np.asarray(returns)
    assert returns.shape[-1] == 128 and np.isfinite(returns).all()  # 128 evaluation episodes
    assert (np.asarray(lengths) <= 20).all()  # episodes end at max_steps_in_episode
