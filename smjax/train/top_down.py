"""Top-down learning with option templates: the paper's Algorithms 1 and 2.

Algorithm 1 visits the hierarchy level by level from the top. For each learnable option
q (the root task first, then each template of the next level, breadth-first) it runs
LearnOptionPolicy and adds the learned option to the policy bank D.

Algorithm 2 (LearnOptionPolicy) is the hierarchical tick of
:mod:`smjax.options.runner`, run for every environment at once: each episode starts
with the root option on the execution stack; the option on top decides; if it picks q
the learner acts and trains; if it picks a template without a learned policy that
template is teleported (one step); otherwise the learned option is pushed and runs.
Options pop when ``satisfied`` or after ``k_max`` ticks. The learner's reward is the
environment's for the root and F_q (its template's ``satisfied``) below, with its
episode capped at q's ``k_max``; so q's start states are exactly the states where the
trained levels above call it. A level stops when its running success reaches the
threshold or its episode budget is spent. Episodes are counted for every environment
episode run, at every level, and summed.
"""
from __future__ import annotations

from pathlib import Path

from smjax.train.config import TrainConfig
from smjax.train.run import run


def train(task, cfg: TrainConfig | None = None, seeds=(0,), out_dir: str | Path | None = None,
          **kwargs) -> dict:
    """Top-down training of ``task``'s hierarchy (see module docstring)."""
    cfg = (cfg or TrainConfig()).replace(method="top-down")
    return run(task, cfg, seeds, out_dir, **kwargs)
