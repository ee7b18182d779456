"""The learners' config dataclasses: which fields are traced, and their validation.

Every field of a learner config is declared ``traced`` or ``static``. A traced field is a
hyper-parameter the learner reads from its state (``state.hp``, a float32 scalar per slot),
so its value is a pytree leaf: the slots of one compiled program (a sweep, fine-tuning's
``finetune_agent``) may each have their own, and changing it compiles nothing new. A static
field fixes shapes or the program's structure (sizes, epochs, minibatches, which code runs)
or is a constant the program closes over; each value compiles its own program. Declaring a
field traced is all it takes to sweep it: ``hyper_params``, the sweep's list of fields and
its error messages all read :func:`traced_fields`.

The declaration lives in the field's metadata rather than in a pytree registration of the
config: a config is hashable, validates itself in ``__post_init__`` (a range check cannot
run on a tracer) and is closed over by the learner's functions, while its traced values
travel in ``state.hp``.

Each config checks itself in ``__post_init__`` so a bad value fails where it was written,
with a message naming the config, the field, the value and the allowed range.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

TRACED = "traced"  # the field metadata key that ``traced`` and ``static`` set


def traced(default: Any) -> Any:
    """A config field the learner reads from ``state.hp`` (a pytree leaf: sweepable)."""
    return dataclasses.field(default=default, metadata={TRACED: True})


def static(default: Any) -> Any:
    """A config field the learner's program is built from (not sweepable)."""
    return dataclasses.field(default=default, metadata={TRACED: False})


def traced_fields(config: Any) -> tuple[str, ...]:
    """The names of the fields of ``config`` (a dataclass or its class) declared
    ``traced``, in declaration order; a field declared neither way is static."""
    return tuple(f.name for f in dataclasses.fields(config) if f.metadata.get(TRACED, False))


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
