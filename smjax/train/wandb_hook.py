"""Weights & Biases logging as a hook of the driver loop (an extra: ``pip install
'smjax[wandb]'``; off unless passed to a run).

    from smjax.train.wandb_hook import WandbHook
    run("craft/get_gem", cfg, seeds, "runs/gem", hooks=[WandbHook(project="smjax")])

Each chunk logs the stages' scalars (the names TensorBoard gets, e.g.
``seed_0/level_1_get_wood/running_success``), each charted against its own env step
(``NAME/env_step``: seeds and levels count env steps apart), then the chunk's number and
the run's env steps per second. Once evaluated, the run's results go to the W&B run's
summary (``run_summary``: results.json's numbers, strings and lists of them, e.g.
``final_success`` per seed and ``final_success_mean``, ``episodes_to_threshold``,
``wall_seconds``, ``compile_seconds``); a sweep's points go to one W&B run, each under its
overrides (``agent.learning_rate=0.001/final_success_mean``). The W&B run finishes after
the last results (where the trainer runs on its own, outside ``smjax.train.run``, when
training ends). A run that fails before its results is left open: W&B closes it when the
process exits, and the hook's next ``start`` finishes it as failed (exit code 1). With
several processes only process 0 logs. ``WANDB_MODE=offline`` keeps everything on disk.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from smjax.train import distributed as dist
from smjax.train.hooks import ChunkReport, Hook, ResultsReport


class WandbHook(Hook):
    """Log every chunk's scalars, and the run's results as its summary, to a W&B run that
    starts with training and finishes once the results are in.

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
        self.results_left = 0  # results calls still to come before the run finishes

    def start(self, trainer) -> None:
        if self.run is not None:  # the hook's last run failed before its results
            self.finish(exit_code=1)
        if dist.is_writer():
            kwargs = dict(self.init_kwargs)  # a hook used for a second run keeps its own
            config = kwargs.pop("config", None) or trainer.cfg.to_dict()
            self.run = self.wandb.init(config=config, **kwargs)
            self.charted = set()

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
        # the results follow evaluation: the run stays open for them, where they come
        self.results_left = getattr(trainer, "results_due", 0)
        if self.results_left <= 0:
            self.finish()

    def results(self, trainer, report: ResultsReport) -> None:
        if self.run is None:
            return
        prefix = "" if report.overrides is None else f"{point_name(report.overrides)}/"
        self.run.summary.update({prefix + k: v for k, v in run_summary(report.results).items()})
        self.results_left -= 1
        if self.results_left <= 0:
            self.finish()

    def finish(self, exit_code: int | None = None) -> None:
        """Finish the W&B run (``exit_code``: nonzero marks it failed)."""
        run, self.run = self.run, None
        if run is not None and exit_code is None:
            run.finish()
        elif run is not None:
            run.finish(exit_code=exit_code)


def point_name(overrides: dict) -> str:
    """A sweep point's name: its overrides, ``agent.learning_rate=0.001,num_envs=64``."""
    return ",".join(f"{k}={v}" for k, v in overrides.items())


def run_summary(results: dict) -> dict:
    """The W&B summary of results.json's content: its numbers, strings and lists of them,
    with the fields of its flat dicts (``finetune``, ``final_success_by_policy``) as
    ``NAME/FIELD``; beside each per-seed list of numbers its mean, ``NAME_mean``, where every
    seed has one (``episodes_to_threshold`` has none where a seed missed the threshold).
    ``config`` (the W&B run's config already), ``levels`` and lists of lists are left out."""
    fields: dict[str, Any] = {}
    for key, value in results.items():
        if key == "config":
            continue
        if isinstance(value, dict):
            fields.update({f"{key}/{k}": v for k, v in value.items()})
        else:
            fields[key] = value
    out: dict[str, Any] = {}
    for key, value in fields.items():
        if _scalar(value):
            out[key] = value
        elif isinstance(value, list) and all(v is None or _scalar(v) for v in value):
            out[key] = value
            numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            if value and numbers and key != "seeds":
                out[f"{key}_mean"] = float(np.mean(value))
    return out


def _scalar(value: Any) -> bool:
    return isinstance(value, (bool, int, float, str))
