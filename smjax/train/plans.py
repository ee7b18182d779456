"""What a run trains, in which order: its hierarchy and the plan of its levels."""
from __future__ import annotations

import warnings
from dataclasses import dataclass

from smjax.options.hierarchy import Hierarchy
from smjax.policy.hierarchies import (DECLARED_PREFIX, FLAT_SUFFIX, PRIMITIVES_ONLY,
                                      hierarchy_named)
from smjax.train import distributed as dist
from smjax.train.config import ConfigError, TrainConfig


@dataclass
class LevelPlan:
    name: str        # option trained
    option: int      # its option id
    start: int       # option at the bottom of the stack at each reset
    level: int       # the paper's level number


@dataclass(frozen=True)
class RunPlan:
    """A run resolved before anything is built from it: its effective config (the root
    threshold lowered where the task's best success demands it, recorded in
    ``cfg.levels``), its hierarchy and that hierarchy's name, and the levels it trains in
    order. Everything the run builds reads ``cfg`` from here."""

    cfg: TrainConfig
    hierarchy_name: str
    hierarchy: Hierarchy
    plans: tuple[LevelPlan, ...]

    @property
    def num_stages(self) -> int:
        """The stages a seed goes through: its levels, and fine-tuning where it runs (as
        ``HierarchyTrainer.num_stages`` counts them)."""
        return len(self.plans) + self.cfg.fine_tuning.on


def resolve_run(env, cfg: TrainConfig, given: Hierarchy | None = None) -> RunPlan:
    """The one resolution of a run's config against its environment: the hierarchy
    (``resolve_hierarchy``), the root's reachable threshold (``reachable_root_threshold``;
    a warning says where it is lowered), the plan of levels, and a check that
    ``cfg.levels`` names only templates the run trains."""
    name, hierarchy = resolve_hierarchy(env, cfg, given)
    effective = reachable_root_threshold(cfg, hierarchy)
    if effective is not cfg and dist.is_writer():
        warnings.warn(f"{env.name}: the best task success is {hierarchy.success_ceiling:g}, so "
                      f"the root level ends at {effective.for_level(hierarchy.task).threshold:g} "
                      f"(ceiling_fraction {cfg.ceiling_fraction:g} of it), not "
                      f"{cfg.for_level(hierarchy.task).threshold:g}", stacklevel=4)
    plans = tuple(plan_levels(hierarchy, effective.method))
    effective.check_level_names([p.name for p in plans])
    return RunPlan(effective, name, hierarchy, plans)


def finetune_order(hierarchy: Hierarchy, cfg: TrainConfig) -> list[LevelPlan]:
    """The options fine-tuning trains, in order (none where it is off)."""
    return plan_levels(hierarchy, "top-down") if cfg.fine_tuning.on else []


def resolve_hierarchy(env, cfg: TrainConfig, given: Hierarchy | None = None
                      ) -> tuple[str, Hierarchy]:
    """The hierarchy a run uses, and its name for results.json and the saved policy
    (:mod:`smjax.policy.hierarchies`): ``given`` (one declared by the caller, named
    ``declared:<task>``), else the named one, else the environment's default (the first
    of its catalogue, ``env.hierarchies()``). The flat method trains that hierarchy's
    flattening (``Hierarchy.flattened``: one level over its leaves), named
    ``<name>:flattened``. An environment that declares none trains flat over its
    primitive actions alone (``primitives:flattened``): flat needs no hierarchy."""
    if given is None and cfg.method == "flat" and cfg.hierarchy is None and not env.hierarchies():
        return PRIMITIVES_ONLY, hierarchy_named(env, PRIMITIVES_ONLY)
    if given is not None:
        if not isinstance(given, Hierarchy):
            raise ConfigError(f"hierarchy must be a name or a smjax.options.Hierarchy (e.g. from "
                              f"declare(env, task, children)), got {type(given).__name__}")
        name = f"{DECLARED_PREFIX}{given.task}"
    else:
        options = env.hierarchies()
        name = next(iter(options), "") if cfg.hierarchy is None else cfg.hierarchy
    if cfg.method == "flat":
        name += FLAT_SUFFIX
    return name, hierarchy_named(env, name, given)


def reachable_root_threshold(cfg: TrainConfig, h: Hierarchy) -> TrainConfig:
    """``cfg`` with the root level's threshold lowered to ``cfg.ceiling_fraction`` of the
    task's best success where it is at or above that best (``Hierarchy.success_ceiling``):
    such a level could only end with every exploring episode perfect, and would spend its
    whole budget (Craft's make_bench, best 0.8: 40,000 episodes). Written into
    ``cfg.levels`` so results and checkpoints record the threshold the level used."""
    ceiling = float(h.success_ceiling)
    if cfg.for_level(h.task).threshold < ceiling - 1e-9:
        return cfg
    levels = dict(cfg.levels)
    levels[h.task] = dict(levels.get(h.task, {}),
                          threshold=round(cfg.ceiling_fraction * ceiling, 6))
    return cfg.replace(levels=levels)


def plan_levels(h: Hierarchy, method: str) -> list[LevelPlan]:
    """Learning order: top-down (root first), bottom-up (deepest first, each from resets)."""
    names = list(h.learnable)
    if method == "flat":
        names = names[:1]
    if method == "bottom-up":
        names = names[::-1]
    plans = []
    for name in names:
        option = h.option_index(name)
        start = option if (method == "bottom-up" and option != 0) else 0
        plans.append(LevelPlan(name, option, start, h.level(name)))
    return plans
