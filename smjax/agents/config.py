"""Validation helpers shared by the learners' config dataclasses.

Each config checks itself in ``__post_init__`` so a bad value fails where it was written,
with a message naming the config, the field, the value and the allowed range.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence


def check_range(
    config: Any,
    field: str,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> None:
    """Require ``low <= value <= high`` (``<`` on an open end); values must be finite numbers."""
    value = getattr(config, field)
    name = type(config).__name__
    lo_sym = "(" if low_open else "["
    hi_sym = ")" if high_open else "]"
    allowed = f"{lo_sym}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi_sym}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name}.{field} must be a finite number in {allowed}, got {value!r}")
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and (value >= high if high_open else value > high)
    if too_low or too_high:
        raise ValueError(f"{name}.{field} must lie in {allowed}, got {value!r}")


def check_positive_int(config: Any, field: str) -> None:
    value = getattr(config, field)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{type(config).__name__}.{field} must be an integer >= 1, got {value!r}")


def check_non_negative_int(config: Any, field: str) -> None:
    value = getattr(config, field)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{type(config).__name__}.{field} must be an integer >= 0, got {value!r}")


def check_hidden_sizes(config: Any, field: str = "hidden_sizes") -> None:
    sizes: Sequence[int] = getattr(config, field)
    ok = isinstance(sizes, (tuple, list)) and all(
        isinstance(s, int) and not isinstance(s, bool) and s >= 1 for s in sizes
    )
    if not ok:
        raise ValueError(
            f"{type(config).__name__}.{field} must be a tuple of positive integers "
            f"(one per hidden layer), got {sizes!r}"
        )


def check_choice(config: Any, field: str, choices: Sequence[str]) -> None:
    value = getattr(config, field)
    if value not in choices:
        raise ValueError(
            f"{type(config).__name__}.{field} must be one of {', '.join(map(repr, choices))}, "
            f"got {value!r}"
        )


def replace_checked(config: Any, **overrides: Any) -> Any:
    """``dataclasses.replace`` that names the valid fields when given an unknown one."""
    valid = [f.name for f in dataclasses.fields(config)]
    unknown = sorted(set(overrides) - set(valid))
    if unknown:
        raise ValueError(
            f"unknown {type(config).__name__} field(s) {unknown}; valid fields: {', '.join(valid)}"
        )
    for name in ("hidden_sizes", "conv_features"):
        if name in overrides and isinstance(overrides[name], list):
            overrides[name] = tuple(overrides[name])  # keep configs hashable
    return dataclasses.replace(config, **overrides)


def check_num_actions(num_actions: Any) -> int:
    """``init``'s action count: a Python int >= 1 (it fixes the network's output shape)."""
    try:
        count = int(num_actions)
    except (TypeError, ValueError):
        raise ValueError(f"num_actions must be an integer >= 1, got {num_actions!r}") from None
    if count < 1 or count != num_actions:
        raise ValueError(f"num_actions must be an integer >= 1, got {num_actions!r}")
    return count


TORSOS = ("mlp", "conv")


def check_torso(config: Any) -> None:
    """``torso`` ("mlp", or "conv": convolutions over the observation's declared grids,
    ``networks.GridEncoder``) and its ``conv_features`` (channels per layer)."""
    check_choice(config, "torso", TORSOS)
    check_hidden_sizes(config, "conv_features")
