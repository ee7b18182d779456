"""Fetch and football train through the same generic trainer (controller templates, no
primitive actions, multi-dimensional actions): tiny DQN runs that must finish and report."""
import numpy as np
import pytest

from smjax.train import TrainConfig
from smjax.train.run import run

TINY = dict(algo="dqn", num_envs=4, rollout_ticks=8, updates_per_chunk=1, max_episodes_per_level=2,
            eval_envs=2, success_window=2, finetune_max_episodes=2,
            agent={"learning_starts": 8, "buffer_capacity": 256, "batch_size": 8})


@pytest.mark.slow  # ~60 s; DQN through the engine also runs in test_train / test_finetune
def test_football_top_down_dqn_smoke():
    res = run("football/11v11_hard", TrainConfig(**TINY, eval_max_ticks=200), [0], progress=False,
              env_overrides={"game_length": 200})
    assert [lvl["template"] for lvl in res["levels"]] == ["win_game", "attack"]
    assert res["levels"][0]["episodes"][0] >= 2
    assert np.isfinite(res["final_return"]).all()  # goal difference of the learned hierarchy


@pytest.mark.slow
def test_fetch_top_down_dqn_smoke():
    res = run("fetch/stack1", TrainConfig(**TINY, eval_max_ticks=60), [0], progress=False)
    assert [lvl["template"] for lvl in res["levels"]] == ["stack", "place_0"]
    assert 0.0 <= res["final_success"][0] <= 1.0  # Fetch reports the paper's score as success
