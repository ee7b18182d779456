"""The one table of numeric bounds for a run's config, checked wherever a config is made.

``TrainConfig`` (the Python API, YAML/JSON files and ``--set`` all end there) checks every
numeric field against ``INT_FIELDS`` / ``FLOAT_FIELDS``: booleans are never numbers, a
numpy or JAX scalar of the right kind counts as its Python value, and every field has an
upper bound, so a value that would overflow an int32 counter or a buffer is refused
before anything compiles, not after training (an evaluation of 2**31 ticks would end a
finished run with an OverflowError). The learner's fields are checked by its own
config (``smjax.agents``); ``check_agent`` adds what depends on the run's batch.
"""
from __future__ import annotations

import math
from typing import Any

INT32_MAX = 2**31 - 1
MAX_ENVS = 2**20  # environments (or episodes) in one batch: far past any memory
MAX_TICKS = 1_000_000  # an episode cap: ticks count in int32 and loops run this long
MAX_COUNT = 2**31 - 1  # episode budgets: counted in int32 on the device
MAX_STEPS = 2**53  # env-step budgets: counted on the host, exact as float64
MAX_WINDOW = 1_000_000  # running-success windows live on the device, [seeds, window]
MAX_LAYER = 16_384  # units of one hidden layer
MAX_REPR = 80  # characters of a bad value an error message repeats

# field: (low, high), both inclusive
INT_FIELDS = {
    "num_envs": (1, MAX_ENVS), "rollout_ticks": (1, 65_536), "updates_per_chunk": (1, 65_536),
    "success_window": (1, MAX_WINDOW), "max_episodes_per_level": (1, MAX_COUNT),
    "max_steps_per_level": (0, MAX_STEPS), "gate_envs": (1, MAX_ENVS),
    "gate_max_ticks": (1, MAX_TICKS), "gate_interval": (1, 1_000_000),
    "eval_envs": (1, MAX_ENVS), "eval_max_ticks": (1, MAX_TICKS), "reset_pool": (0, MAX_ENVS),
    "finetune_turn_episodes": (1, MAX_COUNT), "finetune_max_rest": (0, 1_000_000),
    "finetune_max_episodes": (1, MAX_COUNT), "finetune_plateau_episodes": (0, MAX_COUNT),
}
# field: (low, high, low_open)
FLOAT_FIELDS = {
    "threshold": (0.0, 1.0, True), "ceiling_fraction": (0.0, 1.0, True),
    "gamma": (0.0, 1.0, True), "option_temperature": (0.0, 10.0, True),
    "finetune_threshold": (0.0, 1.0, True), "finetune_option_threshold": (0.0, 1.0, True),
    "finetune_plateau_gain": (0.0, 1.0, False), "finetune_side_cost_weight": (0.0, 100.0, False),
    "level_side_cost_weight": (0.0, 100.0, False),
    # finite: 1e9 and the like mean "only at level boundaries", infinity is a mistake
    "checkpoint_every": (0.0, 1e12, False),
}
# fields that may be None (their default)
NULLABLE = ("reset_pool",)


class BoundsError(ValueError):
    """A value outside its field's type or range; the message names both."""


def short(value: Any) -> str:
    """``repr(value)`` cut to ``MAX_REPR`` characters (a 200 kB value is not echoed)."""
    text = repr(value)
    return text if len(text) <= MAX_REPR else f"{text[:MAX_REPR]}... ({len(text)} characters)"


def as_python(value: Any) -> Any:
    """A numpy/JAX scalar as its Python value (a boolean one stays boolean)."""
    if hasattr(value, "item") and getattr(value, "shape", None) == ():
        return value.item()
    return value


def check_int(name: str, value: Any, low: int, high: int) -> int:
    value = as_python(value)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise BoundsError(f"config field {name!r} = {short(value)}: must be an integer in "
                          f"[{low}, {high}]")
    return value


def check_float(name: str, value: Any, low: float, high: float, low_open: bool) -> float:
    value = as_python(value)
    ok = (not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
          and (value > low if low_open else value >= low) and value <= high)
    if not ok:
        raise BoundsError(f"config field {name!r} = {short(value)}: must be a number in "
                          f"{'(' if low_open else '['}{low:g}, {high:g}]")
    return float(value) if isinstance(value, float) else value


def checked_fields(values: dict) -> dict:
    """``values`` (field -> value) with every numeric field checked against the table and
    numpy scalars made Python numbers; other fields are returned as they are."""
    out = dict(values)
    for name, (low, high) in INT_FIELDS.items():
        if name in out and not (out[name] is None and name in NULLABLE):
            out[name] = check_int(name, out[name], low, high)
    for name, (low, high, low_open) in FLOAT_FIELDS.items():
        if name in out:
            out[name] = check_float(name, out[name], low, high, low_open)
    return out


def check_agent(agent: Any, num_envs: int, rollout_ticks: int) -> None:
    """What a learner config allows alone but this run's batch cannot hold."""
    sizes = getattr(agent, "hidden_sizes", None)
    if sizes is not None and (len(sizes) == 0 or max(sizes) > MAX_LAYER):
        raise BoundsError(f"agent field 'hidden_sizes' = {short(list(sizes))}: must list 1 or "
                          f"more layers of 1 to {MAX_LAYER} units")
    minibatches = getattr(agent, "num_minibatches", None)
    if minibatches is not None:
        # a recurrent learner's minibatches are sets of environments, else of transitions
        items = num_envs if getattr(agent, "recurrent_size", 0) else num_envs * rollout_ticks
        if minibatches > items:
            raise BoundsError(f"agent field 'num_minibatches' = {minibatches}: must be at most "
                              f"the {items} items of a rollout (num_envs x rollout_ticks, or "
                              f"num_envs for a recurrent policy)")


def short_message(text: str, limit: int = 300) -> str:
    """An error message cut to ``limit`` characters (a message that repeats a huge value)."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def strict_json(text: str) -> Any:
    """``json.loads`` that refuses a key given twice (JSON would keep the last silently)."""
    import json

    def pairs(items: list) -> dict:
        out = {}
        for key, value in items:
            if key in out:
                raise ValueError(f"key {short(key)} is given twice")
            out[key] = value
        return out

    return json.loads(text, object_pairs_hook=pairs)


def strict_yaml(text: str) -> Any:
    """``yaml.safe_load`` that refuses aliases (``*name``: a few hundred bytes of them
    expand to gigabytes) and a key given twice (YAML would keep the last silently)."""
    import yaml

    class Loader(yaml.SafeLoader):
        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                mark = self.peek_event().start_mark
                raise ValueError(f"line {mark.line + 1}: aliases (*name) are not allowed in a "
                                 f"config file; write the value out")
            return super().compose_node(parent, index)

        def construct_mapping(self, node, deep=False):
            seen = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                if isinstance(key, (str, int, float, bool)) and key in seen:
                    raise ValueError(f"line {key_node.start_mark.line + 1}: key {short(key)} is "
                                     f"given twice")
                seen.add(key) if isinstance(key, (str, int, float, bool)) else None
            return super().construct_mapping(node, deep=deep)

    return yaml.load(text, Loader=Loader)  # noqa: S506 - a SafeLoader subclass
