"""The flat baseline: one learner for the top task over the environment's "flat"
hierarchy (Craft: the primitive actions; Fetch and football: every lowest-level
template), with the same engine, learner and metrics as the hierarchical methods.
"""
from __future__ import annotations

from pathlib import Path

from smjax.train.config import TrainConfig
from smjax.train.run import run


def train(task, cfg: TrainConfig | None = None, seeds=(0,), out_dir: str | Path | None = None,
          **kwargs) -> dict:
    """Flat training of ``task`` (see module docstring)."""
    cfg = (cfg or TrainConfig()).replace(method="flat")
    return run(task, cfg, seeds, out_dir, **kwargs)
