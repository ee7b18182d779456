"""A convolutional torso over the grids an environment declares (``--agent torso=conv``)."""
import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import smjax
from smjax.agents import make_agent
from smjax.agents.networks import GridEncoder
from smjax.core.layout import Grid, check_layout, flat_rest
from smjax.train import TrainConfig
from smjax.train.run import run


def test_a_layout_is_checked():
    assert check_layout([(0, 2, 2, 3), (12, 1, 1, 2)], 20) == (Grid(0, 2, 2, 3), Grid(12, 1, 1, 2))
    for grids, match in (([(0, 2, 2, 3)], "past the observation"), ([(0, 0, 2, 3)], "size >= 1"),
                         ([(0, 2, 2, 1), (3, 1, 1, 1)], "overlap"), ([(-1, 1, 1, 1)], "start")):
        with pytest.raises(ValueError, match=match):
            check_layout(grids, 10)
    assert flat_rest([Grid(1, 1, 2, 1)], 5) == [0, 3, 4]


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 2), st.integers(1, 3), st.integers(0, 2))
def test_the_encoder_is_a_convolution(i, j, channel):
    # one layer, a single hot cell: moving it inside the grid moves its feature map with it
    # (away from the border, SAME padding), and the values outside the grid pass unchanged
    enc = GridEncoder(((2, 5, 5, 3),), (4,))
    x = jnp.zeros((1, 2 + 75 + 3)).at[0, -3:].set(jnp.asarray([1.0, 2.0, 3.0]))
    params = enc.init(jax.random.PRNGKey(0), x)
    hot = lambda a, b: x.at[0, 2 + (a * 5 + b) * 3 + channel].set(1.0)  # noqa: E731
    feature_map = lambda out: out[0, :100].reshape(5, 5, 4)  # noqa: E731
    here = feature_map(enc.apply(params, hot(i, j)))
    there = feature_map(enc.apply(params, hot(i + 1, j)))
    np.testing.assert_allclose(there[i:i + 3, j - 1:j + 2], here[i - 1:i + 2, j - 1:j + 2], atol=1e-6)
    np.testing.assert_array_equal(enc.apply(params, x)[0, 100:], [0.0, 0.0, 1.0, 2.0, 3.0])


@pytest.mark.parametrize("algo", ["ppo", "dqn", "actor-critic"])
def test_every_learner_reads_the_declared_grids(algo):
    env, params = smjax.make("craft/get_gem")
    obs, _ = env.reset(jax.random.PRNGKey(0), params)
    conv = make_agent(algo, layout=env.observation_layout(params), torso="conv", conv_features=[8])
    state = conv.init(jax.random.PRNGKey(1), obs, 6)
    encoder = state.params["params"]["grid_encoder"]
    chex.assert_shape(encoder["grid_0_conv_0"]["kernel"], (9 * 31, 8))  # a 3 x 3 x 31 patch per cell
    chex.assert_shape(encoder["grid_1_conv_0"]["kernel"], (9 * 31, 8))  # a 3 x 3 x 31 patch per cell
    scores = conv.policy_logits(state.params, jnp.stack([obs, obs]))
    chex.assert_shape(scores, (2, 6))
    chex.assert_tree_all_finite(scores)
    # the default dense torso has no encoder: its parameters are what they always were
    mlp = make_agent(algo, layout=env.observation_layout(params))
    assert "grid_encoder" not in mlp.init(jax.random.PRNGKey(1), obs, 6).params["params"]


def test_a_conv_torso_trains_through_the_engine():
    # (learning itself: test_train.py::test_craft_get_wood_reaches_threshold_on_cpu[conv], slow)
    cfg = TrainConfig(num_envs=8, rollout_ticks=8, updates_per_chunk=2, max_episodes_per_level=40,
                      success_window=16, eval_envs=8, gate=False, finetune="off",
                      agent={"torso": "conv", "conv_features": [4]})
    res = run("craft/get_wood", cfg, [0], progress=False, env_overrides={"observation": "compact"})
    assert res["config"]["agent"]["torso"] == "conv"
    assert "grid_encoder" in res["_raw"]["bank"]["params"]
    assert np.isfinite(res["final_success"]).all()


def test_a_conv_torso_needs_grids_and_no_memory():
    cfg = TrainConfig(num_envs=4, rollout_ticks=4, max_episodes_per_level=4, success_window=4,
                      agent={"torso": "conv"})
    with pytest.raises(ValueError, match="declares none"):
        run("craft/get_wood", cfg, [0], progress=False, env_overrides={"observation": "none"})
    with pytest.raises(ValueError, match="torso='mlp'"):
        make_agent("ppo", torso="conv", recurrent_size=8)
    with pytest.raises(ValueError, match="torso"):
        make_agent("dqn", torso="resnet")
    with pytest.raises(ValueError, match="conv_features"):
        make_agent("ppo", conv_features=(0,))
