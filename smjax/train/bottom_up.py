"""Bottom-up option-value iteration, the paper's main baseline.

Sub-skills are learned first, deepest level first, each from the environment's reset
states (the option is placed at the bottom of the execution stack at every reset, so
no level above is needed); its reward is F_o with episodes capped at ``k_max``. The
levels above are then learned over the already-learned options, which are pushed and
run (SMDP: the caller's transition spans the k ticks its option ran and is discounted
by gamma**k). Templates that are never learned (leaves) are still realised by their
teleport or controller. Same engine, learners, environments and metrics as top-down.
"""
from __future__ import annotations

from pathlib import Path

from smjax.train.config import TrainConfig
from smjax.train.run import run


def train(task, cfg: TrainConfig | None = None, seeds=(0,), out_dir: str | Path | None = None,
          **kwargs) -> dict:
    """Bottom-up training of ``task``'s hierarchy (see module docstring)."""
    cfg = (cfg or TrainConfig()).replace(method="bottom-up")
    return run(task, cfg, seeds, out_dir, **kwargs)
