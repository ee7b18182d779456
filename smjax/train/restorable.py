"""Whether a run's checkpoint can be resumed, decided from its files before anything compiles.

A resume (``run(..., resume=True)``, ``smjax train --resume``) builds its trainer, which
compiles the learner's and the environment's first programs, only after this check: a
checkpoint of another format than ``checkpoint.CHECKPOINT_FORMAT``, a host state that
cannot belong to the run's plan, or a step whose files differ from its manifest is refused
at once, in one line naming the step, whatever the machine's speed.
"""
from __future__ import annotations

from pathlib import Path

from smjax.train import checkpoint as ckpt
from smjax.train import distributed as dist
from smjax.train.manifest import check_host
from smjax.train.state import missing_counter


def check_restorable(out_dir: str | Path, step: str | None, num_slots: int,
                     num_stages: int) -> dict | None:
    """The checkpoint a resume loads (``step``, else the latest; ``ckpt.shared_meta``'s
    info), checked: its format (``ckpt.shared_meta``), its host state against ``num_slots``
    seed slots and ``num_stages`` stages, its files against the step's manifest (on process
    0, which alone reads them; every process raises alike), and that its host state holds
    every counter the trainer reads (``missing_counter``). None when there is none."""
    info = ckpt.shared_meta(out_dir, step)
    if info is None:
        return None
    where = f"checkpoint {info['path']} in {ckpt.checkpoint_dir(out_dir)}"
    host = info["meta"]["host"]
    problem = check_host(host, num_slots, num_stages)
    if problem:
        raise ckpt.CheckpointError(f"{where} cannot belong to this run: {problem}")
    error = None
    if dist.is_writer():
        try:
            ckpt.verify_step(out_dir, info)
        except ckpt.CheckpointError as err:
            error = str(err)
    if dist.is_multiprocess():
        error = dist.broadcast_json(error)
    if error:
        raise ckpt.CheckpointError(error)
    missing = missing_counter(host, num_slots)
    if missing:
        raise ckpt.CheckpointError(f"{where} is damaged: {missing}; resume another step with "
                                   f"--resume-from STEP, or start again with --overwrite")
    return info
