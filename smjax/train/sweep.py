"""Hyper-parameter sweeps in one compiled program.

A sweep ``{"agent.learning_rate": [1e-4, 3e-4], "agent.ent_coef": [0.0, 0.01]}`` trains
the cartesian product of the lists (its *points*) for every seed. Each (point, seed) pair
is one slot of the seed axis: the slot's keys come from its seed alone and its swept
values live in its learner state (``state.hp``, see :mod:`smjax.agents.base`), so every
slot computes exactly what that point's run alone would give for that seed, and the whole
sweep compiles once. Slots are point-major: slot ``p * len(seeds) + i`` is point ``p``,
seed ``seeds[i]``.

Only the fields declared ``traced`` may vary: the learner config's (``agent.NAME``, see
:mod:`smjax.agents.config`) and the trainer's own (:class:`TrainConfig`'s ``gamma``,
a per-slot value of the training chunk). The others fix shapes or the program's
structure; asking for one is refused with a :class:`ConfigError` that lists the
sweepable ones.
"""
from __future__ import annotations

import itertools
import math
from typing import Any

import jax

from smjax.agents.config import traced_fields
from smjax.core.overrides import parse_float
from smjax.train.bounds import short
from smjax.train.config import ConfigError, TrainConfig

PREFIX = "agent."


# points of one sweep at most (each is a slot of every seed, like a seed)
MAX_POINTS = 4096


def sweepable_names(algo: str) -> list[str]:
    """The fields a sweep with learner ``algo`` may vary: TrainConfig's traced fields, then
    the learner config's (as ``agent.NAME``), each in declaration order."""
    from smjax.agents import default_config

    return list(traced_fields(TrainConfig)) + [
        PREFIX + name for name in traced_fields(default_config(algo))]


def _number(key: str, value: Any) -> float:
    try:
        return parse_float(f"sweep {key}", value)
    except ValueError as err:
        raise ConfigError(str(err)) from None


def _integral_field(cfg: TrainConfig, key: str) -> bool:
    """Whether ``key`` is an integer field of its config (a period, a number of steps)."""
    from smjax.agents import make_config

    if key.startswith(PREFIX):
        default = getattr(make_config(cfg.algo), key[len(PREFIX):], None)
    else:
        default = getattr(cfg, key, None)
    return isinstance(default, int) and not isinstance(default, bool)


def _check_value(cfg: TrainConfig, key: str, value: float) -> None:
    """The value must be valid for its config (the config's own range check)."""
    from smjax.agents import make_config

    try:
        if key.startswith(PREFIX):
            make_config(cfg.algo, **(cfg.agent | {key[len(PREFIX):]: value}))
        else:
            cfg.replace(**{key: value})
    except ValueError as err:
        raise ConfigError(f"sweep {key}: {err}") from None


def normalize_sweep(cfg: TrainConfig, sweep: dict) -> dict[str, list[float]]:
    """``sweep`` checked, as ``{"agent.field": [floats]}`` (what a checkpoint records)."""
    if not isinstance(sweep, dict) or not sweep:
        raise ConfigError("a sweep needs at least one field, e.g. {'agent.learning_rate': [1e-4, 3e-4]}")
    allowed = sweepable_names(cfg.algo)
    fixed = sorted(name for name, fields in cfg.levels.items() if "gamma" in fields)
    if "gamma" in sweep and fixed:
        raise ConfigError(f"gamma cannot be swept while levels {fixed} set their own gamma "
                          f"(a level's gamma wins); drop one of the two")
    lists = {}
    for key, values in sweep.items():
        if key not in allowed:
            raise ConfigError(f"{key!r} cannot be swept with algo {cfg.algo!r}; sweepable: "
                              f"{', '.join(allowed) or 'none'}")
        values = list(values) if isinstance(values, (list, tuple)) else [values]
        if not values:
            raise ConfigError(f"sweep {key}: needs at least one value")
        lists[key] = [_number(key, v) for v in values]
        if _integral_field(cfg, key):  # an integer field takes integer values (kept as ints)
            bad = [v for v in lists[key] if not float(v).is_integer()]
            if bad:
                raise ConfigError(f"sweep {key}: needs integer values, got {bad[0]!r}")
            lists[key] = [int(v) for v in lists[key]]
        if len(set(lists[key])) != len(lists[key]):  # a point trained twice over
            raise ConfigError(f"sweep {key}: lists a value twice ({short(values)}); list each once")
        for v in lists[key]:
            _check_value(cfg, key, v)
    count = math.prod(len(v) for v in lists.values())
    if count > MAX_POINTS:  # each point is a slot of every seed: the program grows with them
        raise ConfigError(f"the sweep has {count} points (the product of its lists); at most "
                          f"{MAX_POINTS} train in one program")
    return lists


def sweep_points(lists: dict[str, list[float]]) -> list[dict]:
    """The points (``{"agent.field": value}`` each) of a normalized sweep, in the order of
    ``itertools.product`` over its lists."""
    return [dict(zip(lists, combo)) for combo in itertools.product(*lists.values())]


def parse_sweep_flags(items: list[str]) -> dict[str, list[str]]:
    """``--sweep FIELD=V1,V2`` flags as ``{FIELD: [V1, V2]}`` (values checked by ``run``)."""
    out: dict[str, list[str]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        if not sep or not key.strip() or not values.strip():
            raise ConfigError(f"--sweep must look like FIELD=V1,V2,... (e.g. "
                              f"agent.learning_rate=1e-4,3e-4), got {item!r}")
        if key.strip() in out:
            raise ConfigError(f"--sweep {key.strip()} is given twice; list its values once")
        out[key.strip()] = [v.strip() for v in values.split(",")]
    return out


def slot_layout(cfg: TrainConfig, points: list[dict], seeds: list[int]) -> tuple:
    """Per slot (point-major): its seed, its learner's swept values (per field) and its
    config (its point's: ``point_config``)."""
    slot_seeds = [s for _ in points for s in seeds]
    hp = {key[len(PREFIX):]: [p[key] for p in points for _ in seeds]
          for key in points[0] if key.startswith(PREFIX)}
    configs = [point_config(cfg, p) for p in points]  # one per point, shared by its seeds
    return slot_seeds, hp, [c for c in configs for _ in seeds]


def point_config(cfg: TrainConfig, point: dict) -> TrainConfig:
    """The config that, run alone, is this point."""
    agent = {k[len(PREFIX):]: v for k, v in point.items() if k.startswith(PREFIX)}
    train = {k: v for k, v in point.items() if not k.startswith(PREFIX)}
    return cfg.replace(agent=cfg.agent | agent, **train)


def _slice_lists(record: Any, lo: int, hi: int, num_slots: int) -> Any:
    """Per-slot lists (length ``num_slots``) of a host record, cut to ``[lo, hi)``."""
    if isinstance(record, dict):
        return {k: _slice_lists(v, lo, hi, num_slots) for k, v in record.items()}
    if isinstance(record, list) and len(record) == num_slots:
        return record[lo:hi]
    return record


def point_raw(raw: dict, p: int, num_seeds: int, num_slots: int) -> dict:
    """The trainer's raw results of point ``p`` alone (what its run alone returns)."""
    lo, hi = p * num_seeds, (p + 1) * num_seeds
    out = dict(raw)
    out["levels"] = [_slice_lists(rec, lo, hi, num_slots) for rec in raw["levels"]]
    out["finetune"] = (None if raw.get("finetune") is None
                       else _slice_lists(raw["finetune"], lo, hi, num_slots))
    rows = [(row, slot) for row, slot in zip(raw["curves"], raw["curve_slots"]) if lo <= slot < hi]
    out["curves"] = [row for row, _ in rows]
    out["curve_slots"] = [slot - lo for _, slot in rows]
    cut = lambda x: x[lo:hi]  # noqa: E731
    out["final"] = jax.tree.map(cut, raw["final"])
    out["final_by_policy"] = jax.tree.map(cut, raw["final_by_policy"])
    out["bank"] = jax.tree.map(cut, raw["bank"])
    out["learned"] = raw["learned"][lo:hi]
    out["eval_keys"] = raw["eval_keys"][lo:hi]
    return out
