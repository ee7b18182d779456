"""One entry point for every method: make the env, resolve the hierarchy, train, write results."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from smjax.core.compile_cache import enable_compilation_cache
from smjax.core.registry import make
from smjax.train import checkpoint as ckpt
from smjax.train import distributed as dist
from smjax.train.config import ConfigError, TrainConfig, config_differences
from smjax.train.engine import Engine
from smjax.train.loop import HierarchyTrainer, plan_levels, resolve_hierarchy
from smjax.train.results import build_results, write_results


def validate_seeds(seeds) -> list[int]:
    seeds = list(seeds)
    if not seeds:
        raise ValueError("need at least one seed")
    for s in seeds:
        if not isinstance(s, int) or isinstance(s, bool) or s < 0 or s >= 2**32:
            raise ValueError(f"seeds must be integers in [0, 2**32), got {s!r}")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct, got {seeds}")
    return seeds


def run_identity(task_name: str, cfg: TrainConfig, seeds: list[int], env_overrides: dict) -> dict:
    """What must match for a checkpoint to be resumed."""
    return {"task": task_name, "seeds": seeds, "env_overrides": env_overrides} | cfg.to_dict()


def check_resumable(out_dir, identity: dict) -> bool:
    """True if ``out_dir`` holds a checkpoint of this very run; refuse a different one."""
    info = ckpt.shared_meta(out_dir)
    if info is None:
        return False
    saved = info["meta"]["run"]
    diff = config_differences(saved, identity)
    if diff:
        details = ", ".join(f"{k}: checkpoint {saved.get(k)!r} vs now {identity.get(k)!r}" for k in diff)
        raise ConfigError(f"cannot resume {out_dir}: the run differs in {details}")
    return True


def run(task: str | tuple, cfg: TrainConfig, seeds, out_dir: str | Path | None = None, *,
        env_overrides: dict | None = None, progress: bool = True, resume: bool = False) -> dict:
    """Train ``task`` with ``cfg`` for all ``seeds`` in one compiled program.

    ``task`` is a registered name (``"craft/get_gem"``) or an ``(env, env_params)`` pair
    for environments you define yourself. Returns the results dict (DESIGN.md section 6);
    with ``out_dir`` also writes results.json, curves.csv, curves.png and checkpoints
    there. With several processes (``smjax.train.distributed.initialize`` called first,
    every process running this same call) they train together and only process 0 reads
    and writes ``out_dir``. ``resume=True`` continues from ``out_dir``'s last checkpoint; a checkpoint of
    a different configuration is refused (the error names the differing fields).
    """
    from smjax.agents import make_agent

    enable_compilation_cache()  # a second run of the same programs skips compiling
    seeds = validate_seeds(seeds)
    cfg.validate()
    env_overrides = dict(env_overrides or {})
    if isinstance(task, str):
        env, env_params = make(task, **env_overrides)
    else:
        env, env_params = task
    identity = run_identity(env.name, cfg, seeds, env_overrides)
    # with several processes process 0's view of out_dir decides, so all raise alike
    existing = ckpt.shared_meta(out_dir) if out_dir is not None else None
    if resume:
        if out_dir is None:
            raise ValueError("resume needs the run's output directory")
        if existing is None:
            raise FileNotFoundError(f"nothing to resume: no checkpoint in {ckpt.checkpoint_dir(out_dir)}")
        check_resumable(out_dir, identity)
    elif existing is not None:
        raise FileExistsError(
            f"{out_dir} already holds a checkpointed run; pass resume (--resume) to continue it "
            f"or choose another output directory")
    hierarchy_name, hierarchy = resolve_hierarchy(env, cfg)
    agent = make_agent(cfg.algo, **cfg.agent)
    engine = Engine(env, env_params, hierarchy, agent, cfg)
    trainer = HierarchyTrainer(engine, plan_levels(hierarchy, cfg.method), seeds,
                               out_dir=out_dir, progress=progress, run_meta=identity)
    if resume:
        trainer.restore()
    raw = trainer.run()
    config = cfg.to_dict() | {"hierarchy_used": hierarchy_name, "env_overrides": env_overrides}
    results = build_results(env.name, cfg.method, cfg.algo, seeds, cfg.threshold, raw, config)
    if out_dir is not None and dist.is_writer():
        write_results(out_dir, results, raw["curves"])
    results_with_raw: dict[str, Any] = dict(results)
    results_with_raw["_raw"] = raw
    return results_with_raw
