"""A learner's hyper-parameters are declared ``traced`` or ``static`` on its config fields;
``state.hp``, the sweep's fields and its error messages all follow that declaration."""
import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax.agents
from smjax.agents import ALGOS, PPOConfig, make_agent, make_config, ppo
from smjax.agents import config as checks
from smjax.agents.base import hyper_params
from smjax.agents.config import TRACED, static, traced, traced_fields
from smjax.train import ConfigError, TrainConfig
from smjax.train.sweep import normalize_sweep, sweepable_names

# what each learner reads from its state; a change here changes the learners' programs
EXPECTED = {
    "ppo": ("learning_rate", "gae_lambda", "clip_eps", "ent_coef", "vf_coef", "target_kl"),
    "dqn": ("learning_rate", "target_update_period", "tau", "epsilon_end", "epsilon_decay_steps",
            "reward_scale"),
    "actor-critic": ("learning_rate", "vf_coef", "ent_coef"),
}
STATIC = {"ppo": "update_epochs", "dqn": "epsilon_start", "actor-critic": "hidden_sizes"}


@pytest.mark.parametrize("algo", ALGOS)
def test_the_state_carries_exactly_the_fields_declared_traced(algo):
    config = make_config(algo)
    undeclared = [f.name for f in dataclasses.fields(config) if TRACED not in f.metadata]
    assert undeclared == []  # every field of a learner config is declared one way or the other
    assert traced_fields(config) == EXPECTED[algo]
    state = make_agent(algo).init(jax.random.PRNGKey(0), jnp.zeros(5), 3)
    assert set(state.hp) == set(EXPECTED[algo])
    for name, value in state.hp.items():
        assert value.dtype == jnp.float32 and value.shape == ()
        np.testing.assert_array_equal(value, np.float32(getattr(config, name)))


@pytest.mark.parametrize("algo", ALGOS)
def test_a_sweep_takes_the_traced_fields_and_refuses_a_static_one(algo):
    cfg = TrainConfig(algo=algo)
    allowed = ["gamma"] + ["agent." + name for name in EXPECTED[algo]]
    assert sweepable_names(algo) == allowed
    config = make_config(algo)
    for name in EXPECTED[algo]:  # each traced field sweeps (its default is a valid value)
        key = "agent." + name
        assert normalize_sweep(cfg, {key: [getattr(config, name)]}) == {key: [getattr(config, name)]}
    key = "agent." + STATIC[algo]
    message = f"'{key}' cannot be swept with algo '{algo}'; sweepable: {', '.join(allowed)}"
    with pytest.raises(ConfigError) as err:
        normalize_sweep(cfg, {key: [1, 2]})
    assert str(err.value) == message


def test_the_trainer_traces_gamma_alone():
    # a traced TrainConfig field needs the training chunk to take it per slot, as it takes
    # the discount (sweep.slot_layout, Slots): a new one is more than a declaration
    assert traced_fields(TrainConfig) == ("gamma",)


@dataclass(frozen=True)
class TinyConfig:
    learning_rate: float = traced(1e-3)
    width: int = static(8)
    momentum: float = traced(0.9)


@dataclass(frozen=True)
class PPOWithMomentum(PPOConfig):
    momentum: float = traced(0.9)

    def __post_init__(self):
        super().__post_init__()
        checks.check_range(self, "momentum", 0.0, 1.0)


def test_a_field_declared_traced_is_sweepable_with_no_list_to_edit(monkeypatch):
    assert traced_fields(TinyConfig) == ("learning_rate", "momentum")
    hp = hyper_params(TinyConfig(momentum=0.5))
    assert {k: float(v) for k, v in hp.items()} == {"learning_rate": np.float32(1e-3),
                                                     "momentum": 0.5}
    # a learner config with one more traced field: its state and the sweep take it
    state = ppo.make_agent(PPOWithMomentum()).init(jax.random.PRNGKey(0), jnp.zeros(5), 3)
    assert float(state.hp["momentum"]) == np.float32(0.9)
    monkeypatch.setattr(smjax.agents, "default_config",
                        lambda algo: PPOWithMomentum() if algo == "ppo" else None)
    assert sweepable_names("ppo")[-1] == "agent.momentum"
    cfg = TrainConfig()
    assert normalize_sweep(cfg, {"agent.momentum": [0.5, 0.95]}) == {"agent.momentum": [0.5, 0.95]}
    with pytest.raises(ConfigError, match="momentum must lie in"):
        normalize_sweep(cfg, {"agent.momentum": [1.5]})
    with pytest.raises(ConfigError, match="sweepable: .*agent.target_kl, agent.momentum$"):
        normalize_sweep(cfg, {"agent.update_epochs": [2]})
