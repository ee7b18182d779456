"""benchmarks/fetch_sample_complexity.py: the settings it trains with.

A place_i option runs 23-51 ticks (k_max 80), longer than the 16-tick rollouts: the
decisions still running at a rollout's end are carried into the next (see
smjax/agents/smdp.py), so the rollout length only sets how often the learner updates.
"""
from __future__ import annotations

import argparse
import json

import pytest

from _helpers import BENCHMARKS, load_benchmark
from smjax.envs.fetch.templates import K_MAX

FSC = load_benchmark("fetch_sample_complexity")


def _args(**over):
    base = dict(max_steps=300_000, flat_max_steps=1_200_000, rollout_ticks=0, algo="dqn",
                num_envs=256, threshold=0.85, gamma=FSC.GAMMA, set=None,
                hierarchy="paper_hold", root_gamma=FSC.ROOT_GAMMA, sweep=None)
    return argparse.Namespace(**(base | over))


@pytest.mark.parametrize("blocks", [2, 3, 4])
@pytest.mark.parametrize("method", ["top-down", "flat"])
def test_default_rollouts_are_shorter_than_a_place_option(blocks, method):
    cfg = FSC.level_config(blocks, method, _args(), dict(FSC.AGENT))
    assert cfg.rollout_ticks == 16 < K_MAX["place"]     # pending decisions carry across
    assert FSC.level_config(blocks, method, _args(rollout_ticks=-1),
                            dict(FSC.AGENT)).rollout_ticks == 50 * blocks  # whole episodes
    # two gradient steps per tick at any rollout length
    assert cfg.agent["gradient_steps_per_update"] == 2 * cfg.rollout_ticks
    assert cfg.max_steps_per_level == (1_200_000 if method == "flat" else 300_000)
    # top-down's root may idle only once the tower stands; flat keeps its own hierarchy
    assert cfg.hierarchy == (None if method == "flat" else "paper_hold")
    # levels end on the frozen greedy policy, judged on whole episodes
    assert cfg.gate and cfg.gate_max_ticks >= 50 * blocks
    # top-down's root looks further ahead than its skills (a horizon longer than one place option); flat is unchanged
    assert cfg.gamma == FSC.GAMMA
    assert cfg.levels == ({} if method == "flat" else {"stack": {"gamma": FSC.ROOT_GAMMA}})


def test_a_swept_gamma_leaves_the_root_no_gamma_of_its_own():
    cfg = FSC.level_config(4, "top-down", _args(sweep=["gamma=0.96,0.99"]), dict(FSC.AGENT))
    assert cfg.levels == {}


def test_explicit_rollout_and_agent_override_win():
    agent = dict(FSC.AGENT) | {"gradient_steps_per_update": 7}
    cfg = FSC.level_config(3, "top-down", _args(rollout_ticks=96), agent)
    assert cfg.rollout_ticks == 96
    assert cfg.agent["gradient_steps_per_update"] == 7


def test_negative_rollout_is_refused():
    with pytest.raises(ValueError, match="rollout-ticks"):
        FSC.rollout_ticks_for(3, -2)


def test_ppo_gets_no_dqn_gradient_steps():
    cfg = FSC.level_config(3, "top-down", _args(algo="ppo"), {})
    assert "gradient_steps_per_update" not in cfg.agent


def test_the_fetch_preset_is_the_benchmarks_recipe():
    # configs/fetch_stack3.yaml trains what the script trains
    from smjax.train.config import resolve_config

    levels = {"stack": {"gamma": 0.99}, "place_0": {"threshold": 0.97},
              "place_1": {"threshold": 0.97}, "place_2": {"threshold": 0.97}}
    script = FSC.level_config(3, "top-down", _args(hierarchy="paper_hold_all", num_envs=128,
                                                   max_steps=800_000, set=[f"levels={json.dumps(levels)}"]),
                              dict(FSC.AGENT) | {"gradient_steps_per_update": 128})
    preset = resolve_config(file=BENCHMARKS.parent / "configs" / "fetch_stack3.yaml")
    assert preset == resolve_config(script)
