"""A level's own discount (``TrainConfig.levels[name]["gamma"]``): the learner of that level
trains with it, the other levels with ``cfg.gamma``."""
import jax
import numpy as np
import pytest

from hier_env import make_keydoor
from smjax.train import ConfigError, TrainConfig
from smjax.train.run import run
from smjax.train.sweep import normalize_sweep

CFG = dict(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=200,
           success_window=64, gate_envs=32, eval_envs=32, finetune="off", checkpoint_every=1e9)
LEVELS = ("open_door", "give_key")  # the two levels of keydoor's "paper" hierarchy


def _numbers(cfg: TrainConfig) -> tuple:
    res = run(make_keydoor(), cfg, [0], None, progress=False)
    bank = res["_raw"]["bank"]
    return (res["episodes_to_threshold"], res["final_success"],
            [np.asarray(x) for x in jax.tree.leaves(bank)])


def _same(a: tuple, b: tuple) -> bool:
    return a[:2] == b[:2] and all(np.array_equal(x, y) for x, y in zip(a[2], b[2]))


def test_every_level_given_a_gamma_equals_that_gamma_as_the_default():
    by_level = TrainConfig(**CFG, gamma=0.99, levels={name: {"gamma": 0.9} for name in LEVELS})
    default = TrainConfig(**CFG, gamma=0.9)
    other = TrainConfig(**CFG, gamma=0.99)
    numbers = _numbers(by_level)
    assert _same(numbers, _numbers(default))
    assert not _same(numbers, _numbers(other))  # the discount does matter here


def test_a_swept_gamma_is_refused_where_a_level_sets_its_own():
    cfg = TrainConfig(**CFG, algo="dqn", levels={"open_door": {"gamma": 0.99}})
    with pytest.raises(ConfigError, match="gamma cannot be swept"):
        normalize_sweep(cfg, {"gamma": [0.9, 0.95]})


def test_a_level_gamma_is_checked_like_gamma():
    with pytest.raises(ConfigError, match="levels.*'give_key'.*gamma"):
        TrainConfig(**CFG, levels={"give_key": {"gamma": 1.5}})
