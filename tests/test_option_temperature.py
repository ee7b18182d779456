"""The templates' own sampling temperature (``TrainConfig.option_temperature``): the root
samples at 1, every template below it at the configured temperature, in training, gates
and the final "sample" evaluation; every evaluation mode has one temperature per option."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hier_env import KeyDoor, make_keydoor
from smjax.options.bank import frozen_temperature
from smjax.options.runner import Controls, HierarchyRunner
from smjax.train import ConfigError, TrainConfig
from smjax.train.engine import EVAL_TEMPERATURES, eval_temperatures
from smjax.train.run import run
from test_runner import fixed_agent


def test_every_mode_gives_one_temperature_per_option_and_the_root_its_own():
    np.testing.assert_allclose(eval_temperatures("greedy", 3), [0, 0, 0])
    np.testing.assert_allclose(eval_temperatures("sample", 3), [1, 1, 1])
    np.testing.assert_allclose(eval_temperatures("sample", 3, 0.25), [1, 0.25, 0.25])
    np.testing.assert_allclose(eval_temperatures("sample_t0.5", 2, 0.25), [0.5, 0.5])
    np.testing.assert_allclose(eval_temperatures("options_t0.5", 4), [1, .5, .5, .5])
    with pytest.raises(ValueError, match="policy must be one of"):
        eval_temperatures("coldest", 3)
    assert set(EVAL_TEMPERATURES) == {"greedy", "sample", "sample_t0.5", "options_t0.5"}


@pytest.mark.parametrize("value", [0, -1.0, 11.0, True, "cold"])
def test_bad_option_temperatures_are_refused(value):
    with pytest.raises(ConfigError, match="option_temperature"):
        TrainConfig(option_temperature=value)


@pytest.mark.parametrize("value", ["greedy", "", None, 1, ["all"]])
def test_bad_eval_policies_are_refused(value):
    with pytest.raises(ConfigError, match="eval_policies"):
        TrainConfig(eval_policies=value)


def test_a_run_samples_its_templates_at_the_option_temperature():
    cfg = TrainConfig(num_envs=8, rollout_ticks=8, updates_per_chunk=2, success_window=32,
                      gate_envs=16, eval_envs=16, max_episodes_per_level=150,
                      finetune_max_episodes=160, finetune_turn_episodes=80,
                      option_temperature=0.5, eval_policies="all")
    res = run(make_keydoor(), cfg, [0], progress=False)
    assert 0.0 <= res["final_success"][0] <= 1.0
    # "sample" (the run's mode) now is the root at 1 and give_key at 0.5, as options_t0.5
    by_policy = res["final_success_by_policy"]
    assert set(by_policy) == set(EVAL_TEMPERATURES)  # every mode, as eval_policies asks
    assert by_policy["sample"] == by_policy["options_t0.5"] == res["final_success"]


def test_a_run_samples_the_root_at_its_temperature_and_templates_at_theirs():
    # the tick's temperature (Controls.temperature) of a run's frozen-policy mode
    np.testing.assert_allclose(frozen_temperature("sample", 0.5, 2), [1.0, 0.5])
    same = frozen_temperature("sample", 1.0, 2)
    assert isinstance(same, float) and same == 1.0  # one float: no per-option pick
    greedy = frozen_temperature("greedy", 0.5, 2)
    assert isinstance(greedy, float) and greedy == 0.0  # the argmax alone
    with pytest.raises(ValueError, match="option_temperature"):
        frozen_temperature("sample", 0.0, 2)


def test_the_tick_picks_at_the_runs_temperature():
    # the root's frozen policy samples at 1 while the template below it picks greedily
    env = KeyDoor()
    h = env.hierarchies()["paper"]
    runner = HierarchyRunner(env, env.default_params, h, fixed_agent(0, h.num_actions))
    controls = Controls(jnp.asarray(0), jnp.asarray(0), jnp.asarray([True, True]), gamma=0.9,
                        temperature=frozen_temperature("sample", 1e-3, h.num_options))
    flat = jnp.zeros((2, 512, h.num_actions)).at[:, :, 2].set(0.5)  # nearly uniform scores
    picks = np.asarray(runner._frozen_pick(flat, jax.random.PRNGKey(3), controls))
    assert len(set(picks[0].tolist())) == h.num_actions  # the root: a sample
    assert (picks[1] == 2).all()                          # the template: nearly the argmax
