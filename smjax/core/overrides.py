"""Strict parsing of override values, the same for every environment, config and learner.

Values arrive as Python objects (the API, YAML, JSON) or as text (the command line:
``--env checkpoint_reward=no``). Each parser accepts exactly the spellings of its type
and refuses everything else with a ``ValueError`` that names the field, the value and
the allowed range:

- booleans: True/False, 1/0, and the words true/false, yes/no, on/off (any case);
  never ``bool(x)``, which makes the string "False" true;
- integers: ints, integral floats (3.0) and their text; never truncated (2.7 is refused);
- floats: finite numbers and their text (NaN and infinities are refused).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

TRUE_WORDS = ("true", "1", "yes", "on")
FALSE_WORDS = ("false", "0", "no", "off")
INT32_MAX = 2**31 - 1


def _short(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters: an error never echoes a huge value."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def _interval(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    """`` in [low, high]`` (open ends as parentheses); empty when there are no bounds."""
    if low is None and high is None:
        return ""
    lo = "(" if low_open or low is None else "["
    hi = ")" if high_open or high is None else "]"
    return f" in {lo}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi}"


def _check_range(name: str, value: float, low, high, low_open: bool, high_open: bool,
                 kind: str) -> None:
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and (value >= high if high_open else value > high)
    if too_low or too_high:
        raise ValueError(f"{name} must be {kind}{_interval(low, high, low_open, high_open)}, "
                         f"got {_short(value)}")


def parse_bool(name: str, value: Any) -> bool:
    """``value`` as a bool; only the spellings listed in the module docstring."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    if isinstance(value, str):
        word = value.strip().lower()
        if word in TRUE_WORDS:
            return True
        if word in FALSE_WORDS:
            return False
    if hasattr(value, "dtype") and getattr(value, "shape", None) == () and value.dtype == bool:
        return bool(value)  # a numpy / JAX boolean scalar
    raise ValueError(f"{name} must be true or false (also 1/0, yes/no, on/off), got {_short(value)}")


def _number(name: str, value: Any, kind: str) -> float | int:
    """A real number from a number or its text; bools and other types are refused."""
    if isinstance(value, bool) or value is None:
        raise ValueError(f"{name} must be {kind}, got {_short(value)}")
    if isinstance(value, str):
        text = value.strip()
        try:
            return int(text)
        except ValueError:
            pass
        try:
            return float(text)
        except ValueError:
            raise ValueError(f"{name} must be {kind}, got {_short(value)}") from None
    if hasattr(value, "item") and getattr(value, "shape", None) == ():
        value = value.item()  # numpy / JAX scalar
        if isinstance(value, bool):
            raise ValueError(f"{name} must be {kind}, got {_short(value)}")
    if not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be {kind}, got {type(value).__name__} {_short(value)}")
    return value


def parse_int(name: str, value: Any, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int in ``[low, high]``; a non-integral number is refused, not truncated."""
    kind = "an integer"
    number = _number(name, value, kind)
    if isinstance(number, float):
        if not math.isfinite(number) or not number.is_integer():
            raise ValueError(f"{name} must be {kind}{_interval(low, high, False, False)}, "
                             f"got {_short(value)}")
        number = int(number)
    _check_range(name, number, low, high, False, False, kind)
    return number


def parse_float(name: str, value: Any, low: float | None = None, high: float | None = None, *,
                low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a finite float in the given interval (open ends on request)."""
    kind = "a finite number"
    number = float(_number(name, value, kind))
    if not math.isfinite(number):
        raise ValueError(f"{name} must be {kind}{_interval(low, high, low_open, high_open)}, "
                         f"got {_short(value)}")
    _check_range(name, number, low, high, low_open, high_open, kind)
    return number


def parse_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, choices))}, got {_short(value)}")
    return value


def parse_int_list(name: str, value: Any, low: int = 1) -> tuple[int, ...]:
    """A sequence of integers (hidden layer sizes), as a tuple."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
        raise ValueError(f"{name} must be a list of integers >= {low}, got {_short(value)}")
    return tuple(parse_int(f"{name}[{i}]", v, low) for i, v in enumerate(value))


def coerce_like(name: str, value: Any, default: Any) -> Any:
    """Parse ``value`` as the type of ``default`` (a field's default value): the shared rule
    for dataclass configs, whose field types show in their defaults."""
    if isinstance(default, bool):
        return parse_bool(name, value)
    if isinstance(default, int):
        return parse_int(name, value)
    if isinstance(default, float):
        return parse_float(name, value)
    if isinstance(default, tuple) and all(isinstance(d, int) for d in default):
        return parse_int_list(name, value)
    return value


def coerce_annotated(name: str, value: Any, annotation: Any, default: Any) -> Any:
    """Parse ``value`` by a parameter's annotation (``"bool"``, ``"int | None"``, ...; the
    string form under ``from __future__ import annotations``), else by its default."""
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    parts = [p.strip() for p in text.split("|")]
    if value is None and ("None" in parts or default is None):
        return None
    base = [p for p in parts if p != "None"]
    kind = base[0] if len(base) == 1 else None
    if kind == "bool":
        return parse_bool(name, value)
    if kind == "int":
        return parse_int(name, value)
    if kind == "float":
        return parse_float(name, value)
    if kind == "str":
        if not isinstance(value, str):
            raise ValueError(f"{name} must be a string, got {_short(value)}")
        return value
    return coerce_like(name, value, default)
