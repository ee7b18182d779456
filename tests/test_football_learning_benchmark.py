"""benchmarks/football_learning.py: equal budgets and agent settings for both methods."""
from __future__ import annotations

import argparse

import pytest

from smjax.train.bounds import MAX_WINDOW

from _helpers import load_benchmark

FL = load_benchmark("football_learning")


def _args(num_envs=64, total=2_100_000, stop=False):
    return argparse.Namespace(num_envs=num_envs, total_steps=total, eval_games=8,
                              stop_at_threshold=stop, reset_after_option=False)


def _budget_used(cfg, chunk):
    """Env steps a run can use at most: each level stops at the first chunk >= its budget."""
    names = ["win_game", "attack"] if cfg.method == "top-down" else ["win_game"]
    total = 0
    for name in names:
        budget = cfg.for_level(name).max_steps_per_level
        total += -(-budget // chunk) * chunk
    return total


@pytest.mark.parametrize("num_envs,total", [(64, 2_100_000), (128, 2_100_000), (100, 700_000)])
def test_both_methods_fit_the_same_total_budget(num_envs, total):
    args = _args(num_envs, total)
    agent = FL.parse_agent([], num_envs)
    chunk = num_envs * FL.ROLLOUT_TICKS * 4
    td, flat = FL.make_config("top-down", args, agent), FL.make_config("flat", args, agent)
    used_td, used_flat = _budget_used(td, chunk), _budget_used(flat, chunk)
    assert used_td <= total and used_flat <= total
    assert used_td == used_flat                      # same budget, to the chunk
    assert td.for_level("win_game").max_steps_per_level == 1      # one chunk: its choice is forced
    assert td.agent == flat.agent and td.gamma == flat.gamma and td.num_envs == flat.num_envs
    assert td.success_window == flat.success_window == MAX_WINDOW   # run the whole budget


def test_threshold_stop_is_opt_in_and_tiny_budgets_are_refused():
    agent = FL.parse_agent([], 64)
    assert FL.make_config("flat", _args(stop=True), agent).success_window == 256
    with pytest.raises(ValueError, match="two chunks"):
        FL.make_config("flat", _args(total=10_000), agent)
    with pytest.raises(ValueError, match="unknown method"):
        FL.make_config("bottom-up", _args(), agent)


def test_gradient_steps_scale_with_envs_and_overrides_apply():
    assert FL.parse_agent([], 64)["gradient_steps_per_update"] == 8
    assert FL.parse_agent([], 128)["gradient_steps_per_update"] == 16
    agent = FL.parse_agent(["hidden_sizes=(256,256)", "learning_rate=1e-3"], 64)
    assert agent["hidden_sizes"] == (256, 256) and agent["learning_rate"] == 1e-3
    with pytest.raises(SystemExit):
        FL.parse_agent(["oops"], 64)


def test_table_lists_every_run_with_the_paper_number():
    rec = {"difficulty": "hard", "method": "top-down", "goal_difference": [2.0, 3.0],
           "env_steps": [2_097_152, 2_097_152], "paper": 2.0, "wall_seconds": 10.0,
           "compile_seconds": 3.0,
           "levels": [{"template": "win_game", "env_steps": [8192, 8192]},
                      {"template": "attack", "env_steps": [2_088_960, 2_088_960]}]}
    text = FL.table([rec])
    assert "| hard | top-down | +2.50 +- 0.50 (2 seeds) | 2.10M |" in text
    assert "win_game 0.01M, attack 2.09M" in text and "+2.00" in text
