"""Whether a run's checkpoint can be resumed, decided from its files before anything compiles.

A resume (``run(..., resume=True)``, ``smjax render --policy``) builds its trainer, which
compiles the learner's and the environment's first programs, only after this check: a
checkpoint of another format, a host state that cannot belong to the run's plan, or a
step whose files differ from its manifest is refused at once, in one line naming the
step, whatever the machine's speed.
"""
from __future__ import annotations

from pathlib import Path

from smjax.train import checkpoint as ckpt
from smjax.train import distributed as dist
from smjax.train.manifest import check_host

# the oldest checkpoint format a resume migrates (the first whose learner states hold their
# hyper-parameters)
OLDEST_FORMAT = 2


def check_restorable(out_dir: str | Path, step: str | None, num_slots: int, num_stages: int,
                     newest: int) -> tuple[dict, int] | None:
    """The checkpoint a resume loads (``step``, else the latest) and its format, checked:
    its format in ``OLDEST_FORMAT..newest``, its host state against ``num_slots`` seed
    slots and ``num_stages`` stages, its files against the step's manifest (on process 0,
    which alone reads them; every process raises alike). None when there is none."""
    info = ckpt.shared_meta(out_dir, step)
    if info is None:
        return None
    version = ckpt.check_format(out_dir, info["meta"], OLDEST_FORMAT, newest)
    problem = check_host(info["meta"]["host"], num_slots, num_stages)
    if problem:
        raise ckpt.CheckpointError(f"checkpoint {info['path']} in {ckpt.checkpoint_dir(out_dir)} "
                                   f"cannot belong to this run: {problem}")
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
    return info, version
