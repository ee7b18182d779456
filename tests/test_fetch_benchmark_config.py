"""benchmarks/fetch_sample_complexity.py: rollouts long enough for the root's place options.

A place_i option runs 23-51 ticks (k_max 80). With rollouts shorter than that every root
decision was cut at a rollout end and bootstrapped from a mid-option state, so the root
never learned what a place did (measured: a random root's score). These tests pin the
settings that keep place decisions whole.
"""
from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import pytest

from smjax.envs.fetch.templates import K_MAX

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "fetch_sample_complexity.py"
_spec = importlib.util.spec_from_file_location("fetch_sample_complexity", _PATH)
FSC = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(FSC)


def _args(**over):
    base = dict(max_steps=300_000, flat_max_steps=1_200_000, rollout_ticks=0, algo="dqn",
                num_envs=256, threshold=0.85, gamma=FSC.GAMMA, set=None,
                hierarchy="paper_hold")
    return argparse.Namespace(**(base | over))


@pytest.mark.parametrize("blocks", [2, 3, 4])
@pytest.mark.parametrize("method", ["top-down", "flat"])
def test_default_rollout_spans_an_episode_and_drops_cut_decisions(blocks, method):
    cfg = FSC.level_config(blocks, method, _args(), dict(FSC.AGENT))
    assert cfg.rollout_ticks == 50 * blocks            # one whole episode
    assert cfg.rollout_ticks >= K_MAX["place"]          # a place option fits in a rollout
    # the same gradient steps per env step as the former 32 per 16-tick rollout
    assert cfg.agent["gradient_steps_per_update"] == 2 * cfg.rollout_ticks
    assert cfg.max_steps_per_level == (1_200_000 if method == "flat" else 300_000)
    # top-down's root may idle only once the tower stands; flat keeps its own hierarchy
    assert cfg.hierarchy == (None if method == "flat" else "paper_hold")


def test_explicit_rollout_and_agent_override_win():
    agent = dict(FSC.AGENT) | {"gradient_steps_per_update": 7}
    cfg = FSC.level_config(3, "top-down", _args(rollout_ticks=96), agent)
    assert cfg.rollout_ticks == 96
    assert cfg.agent["gradient_steps_per_update"] == 7


def test_negative_rollout_is_refused():
    with pytest.raises(ValueError, match="rollout-ticks"):
        FSC.rollout_ticks_for(3, -1)


def test_ppo_gets_no_dqn_gradient_steps():
    cfg = FSC.level_config(3, "top-down", _args(algo="ppo"), {})
    assert "gradient_steps_per_update" not in cfg.agent
