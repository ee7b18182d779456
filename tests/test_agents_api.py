"""Agent interface: construction, config validation, masking, policy bank (all algos)."""
from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smjax.agents import ALGOS, DQNConfig, PPOConfig, ActorCriticConfig, make_agent, make_config
from smjax.agents.flat_train import FlatTrainConfig

NUM_ACTIONS = 5
OBS = jnp.zeros((3, 2), jnp.uint8)  # any shape and dtype: agents flatten and cast
# greedy DQN so the argmax path (not only the uniform one) is exercised
OVERRIDES = {"ppo": {}, "actor-critic": {}, "dqn": {"epsilon_start": 0.0, "epsilon_end": 0.0}}


def _agent_and_state(algo, **extra):
    agent = make_agent(algo, **{**OVERRIDES[algo], **extra})
    return agent, agent.init(jax.random.PRNGKey(0), OBS, NUM_ACTIONS)


def test_algos_listed_and_named():
    assert ALGOS == ("ppo", "dqn", "actor-critic")
    for algo in ALGOS:
        assert make_agent(algo).name == algo


def test_unknown_algo_and_field_errors_list_valid_choices():
    with pytest.raises(ValueError, match="ppo, dqn, actor-critic"):
        make_agent("sac")
    with pytest.raises(ValueError, match=r"learning_rat\b.*valid fields:.*learning_rate"):
        make_agent("ppo", learning_rat=1e-3)


@pytest.mark.parametrize("config_cls, field, bad", [
    (PPOConfig, "clip_eps", -0.1), (PPOConfig, "gamma", 1.5), (PPOConfig, "num_minibatches", 0),
    (PPOConfig, "hidden_sizes", (64, 0)), (PPOConfig, "activation", "sigmoidish"),
    (PPOConfig, "learning_rate", float("nan")),
    (DQNConfig, "tau", 0.0), (DQNConfig, "buffer_capacity", 0), (DQNConfig, "learning_starts", -1),
    (DQNConfig, "epsilon_schedule_unit", "episodes"), (DQNConfig, "batch_size", 2.5),
    (ActorCriticConfig, "epsilon_min", 2.0), (ActorCriticConfig, "learning_rate", 0.0),
    (FlatTrainConfig, "num_envs", 0), (FlatTrainConfig, "gamma", -0.5),
])
def test_config_validation_names_the_field(config_cls, field, bad):
    with pytest.raises(ValueError, match=field):
        config_cls(**{field: bad})


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("bad", [0, -2, 2.5, "three"])
def test_init_rejects_bad_action_counts(algo, bad):
    with pytest.raises(ValueError, match="num_actions"):
        make_agent(algo).init(jax.random.PRNGKey(0), OBS, bad)


def test_make_config_accepts_list_hidden_sizes():
    assert make_config("ppo", hidden_sizes=[32]).hidden_sizes == (32,)


mask_rows = st.lists(st.booleans(), min_size=NUM_ACTIONS, max_size=NUM_ACTIONS).filter(any)


@pytest.mark.parametrize("algo", ALGOS)
@settings(max_examples=25, deadline=None)
# a fixed batch of 6 rows keeps one compiled program for all examples
@given(masks=st.lists(mask_rows, min_size=6, max_size=6), seed=st.integers(0, 2**31 - 1))
def test_masked_actions_never_chosen(algo, masks, seed):
    agent, state = _AGENTS[algo]
    mask = jnp.array(masks, bool)
    obs = jax.random.randint(jax.random.PRNGKey(seed), (len(masks),) + OBS.shape, 0, 2).astype(jnp.uint8)
    keys = jax.random.split(jax.random.PRNGKey(seed), 16)
    out = _ACT[algo](state, obs, mask, keys)
    chosen_allowed = np.take_along_axis(np.asarray(mask)[None], np.asarray(out.action)[..., None], -1)
    assert chosen_allowed.all()
    chex.assert_tree_all_finite(out)
    chex.assert_type(out.action, jnp.int32)


def _biased_towards_action0(algo, state):
    """Params whose greedy choice is overwhelmingly action 0."""
    head = "q_head" if algo == "dqn" else "policy_head"
    params = jax.tree.map(lambda x: x, state.params)
    bias = params["params"][head]["bias"]
    params["params"][head]["bias"] = bias.at[0].set(1e4)
    return state.replace(params=params)


@pytest.mark.parametrize("algo", ALGOS)
def test_strongly_preferred_masked_action_is_still_excluded(algo):
    agent, state = _agent_and_state(algo)
    state = _biased_towards_action0(algo, state)
    mask = jnp.ones((64, NUM_ACTIONS), bool).at[:, 0].set(False)
    out = agent.act(state, jnp.ones((64,) + OBS.shape, jnp.uint8), mask, jax.random.PRNGKey(1))
    assert not np.any(np.asarray(out.action) == 0)
    chex.assert_tree_all_finite(out)
    unmasked = agent.act(state, jnp.ones((64,) + OBS.shape, jnp.uint8), jnp.ones_like(mask),
                         jax.random.PRNGKey(1))
    if algo != "actor-critic":  # actor-critic starts with epsilon = 1 (uniform exploration)
        assert np.all(np.asarray(unmasked.action) == 0)


def test_behaviour_log_probs_are_those_of_the_sampling_distribution():
    mask = jnp.array([[True, False, True, True, False]] * 4)
    obs = jnp.ones((4,) + OBS.shape, jnp.uint8)
    agent, state = _agent_and_state("ppo")
    out = agent.act(state, obs, mask, jax.random.PRNGKey(2))
    logits = jnp.where(mask, agent.policy_logits(state.params, obs), -jnp.inf)
    expected = jax.nn.log_softmax(logits)[jnp.arange(4), out.action]
    np.testing.assert_allclose(out.log_prob, expected, rtol=1e-5)
    # actor-critic before any episode: epsilon = 1, uniform over the 3 allowed actions
    agent, state = _agent_and_state("actor-critic")
    out = agent.act(state, obs, mask, jax.random.PRNGKey(2))
    np.testing.assert_allclose(out.log_prob, np.log(1 / 3), rtol=1e-5)
    # greedy DQN: probability 1 for the greedy action; value = best allowed Q
    agent, state = _agent_and_state("dqn")
    out = agent.act(state, obs, mask, jax.random.PRNGKey(2))
    np.testing.assert_allclose(out.log_prob, 0.0, atol=1e-6)
    q = np.where(mask, agent.policy_logits(state.params, obs), -np.inf)
    np.testing.assert_allclose(out.value, q.max(-1), rtol=1e-5)


@pytest.mark.parametrize("algo", ALGOS)
def test_policy_bank_of_stacked_params(algo):
    agent = make_agent(algo)
    params = [agent.init(jax.random.PRNGKey(i), OBS, NUM_ACTIONS).params for i in range(3)]
    bank = jax.tree.map(lambda *x: jnp.stack(x), *params)
    obs = jax.random.randint(jax.random.PRNGKey(7), (6,) + OBS.shape, 0, 2).astype(jnp.uint8)
    stacked = jax.jit(jax.vmap(agent.policy_logits, in_axes=(0, None)))(bank, obs)
    chex.assert_shape(stacked, (3, 6, NUM_ACTIONS))
    for i, p in enumerate(params):
        np.testing.assert_allclose(stacked[i], agent.policy_logits(p, obs), rtol=1e-5, atol=1e-6)
    assert not np.allclose(stacked[0], stacked[1])  # different inits, different policies


_AGENTS = {algo: _agent_and_state(algo) for algo in ALGOS}
# one compiled "act under 16 keys" per algo, shared by the hypothesis examples
_ACT = {
    algo: jax.jit(jax.vmap(_AGENTS[algo][0].act, in_axes=(None, None, None, 0)))
    for algo in ALGOS
}
