"""Weights & Biases logging as a hook of the driver loop (an extra: ``pip install
'smjax[wandb]'``; off unless passed to a run).

    from smjax.train.wandb_hook import WandbHook
    run("craft/get_gem", cfg, seeds, "runs/gem", hooks=[WandbHook(project="smjax")])

Each chunk logs the stages' scalars (the names TensorBoard gets, e.g.
``seed_0/level_1_get_wood/running_success``), each charted against its own env step
(``NAME/env_step``: seeds and levels count env steps apart), then the chunk's number and
the run's env steps per second. With several processes only process 0 logs.
``WANDB_MODE=offline`` keeps everything on disk.
"""
from __future__ import annotations

from typing import Any

from smjax.train import distributed as dist
from smjax.train.hooks import ChunkReport, Hook


class WandbHook(Hook):
    """Log every chunk's scalars to a W&B run that starts with training and ends with it.

    ``init_kwargs`` go to ``wandb.init`` (``project``, ``entity``, ``name``, ``mode``,
    ``dir``, ...); the run's config (``TrainConfig.to_dict()``) is its ``config`` unless
    given."""

    def __init__(self, **init_kwargs: Any):
        try:
            import wandb
        except ImportError:
            raise ImportError("WandbHook needs the wandb package: pip install 'smjax[wandb]' "
                              "(or pip install wandb)") from None
        self.wandb, self.init_kwargs, self.run = wandb, init_kwargs, None
        self.charted: set[str] = set()  # names whose x axis is declared

    def start(self, trainer) -> None:
        if self.run is None and dist.is_writer():
            kwargs = dict(self.init_kwargs)  # a hook used for a second run keeps its own
            config = kwargs.pop("config", None) or trainer.cfg.to_dict()
            self.run = self.wandb.init(config=config, **kwargs)

    def chunk(self, trainer, report: ChunkReport) -> None:
        if self.run is None:
            return
        for scalar in report.scalars:  # a name may come several times, at its env steps
            x_axis = f"{scalar.name}/env_step"
            if scalar.name not in self.charted:
                self.run.define_metric(scalar.name, step_metric=x_axis)
                self.charted.add(scalar.name)
            self.run.log({scalar.name: scalar.value, x_axis: scalar.step})
        self.run.log({"chunk": report.chunk,
                      "env_steps_per_second": report.steps / max(report.seconds, 1e-9)})

    def end(self, trainer) -> None:
        if self.run is not None:
            self.run.finish()
            self.run = None
