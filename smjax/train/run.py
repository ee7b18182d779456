"""One entry point for every method: make the env, resolve the hierarchy, train, write results."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from smjax.core.registry import make
from smjax.train.config import TrainConfig
from smjax.train.engine import Engine
from smjax.train.loop import plan_levels, resolve_hierarchy, train_hierarchy
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


def run(task: str | tuple, cfg: TrainConfig, seeds, out_dir: str | Path | None = None, *,
        env_overrides: dict | None = None, progress: bool = True) -> dict:
    """Train ``task`` with ``cfg`` for all ``seeds`` in one compiled program.

    ``task`` is a registered name (``"craft/get_gem"``) or an ``(env, env_params)`` pair
    for environments you define yourself. Returns the results dict (DESIGN.md section 6);
    with ``out_dir`` also writes results.json, curves.csv and curves.png there.
    """
    from smjax.agents import make_agent

    seeds = validate_seeds(seeds)
    cfg.validate()
    env_overrides = dict(env_overrides or {})
    if isinstance(task, str):
        env, env_params = make(task, **env_overrides)
    else:
        env, env_params = task
    hierarchy_name, hierarchy = resolve_hierarchy(env, cfg)
    agent = make_agent(cfg.algo, **cfg.agent)
    engine = Engine(env, env_params, hierarchy, agent, cfg)
    plans = plan_levels(hierarchy, cfg.method)
    raw = train_hierarchy(engine, plans, seeds, progress=progress)
    config = cfg.to_dict() | {"hierarchy_used": hierarchy_name, "env_overrides": env_overrides}
    results = build_results(env.name, cfg.method, cfg.algo, seeds, cfg.threshold, raw, config)
    if out_dir is not None:
        write_results(out_dir, results, raw["curves"])
    results_with_raw: dict[str, Any] = dict(results)
    results_with_raw["_raw"] = raw
    return results_with_raw
