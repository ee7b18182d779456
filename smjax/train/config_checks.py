"""The rules a training configuration must satisfy, and the parsing of its values.

Kept apart from :class:`smjax.train.config.TrainConfig` (which calls them once, when a
config is made) so that the reference of its fields and the rules between them each stay
readable; the functions take any object with ``TrainConfig``'s fields.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

from smjax.options.memory import POLICY_MEMORIES
from smjax.train.bounds import BoundsError, check_agent, checked_fields, short, short_message

METHODS = ("top-down", "bottom-up", "flat")
ALGOS = ("ppo", "dqn", "actor-critic")
FROZEN_POLICIES = ("auto", "greedy", "sample")
EVAL_POLICIES = ("run", "all")
FINETUNE_CHOICES = ("auto", "on", "off")
FINETUNE_MODES = ("turns", "joint")
# what ``TrainConfig.levels`` may override per template
LEVEL_FIELDS = ("threshold", "max_episodes_per_level", "max_steps_per_level", "success_window",
                "gamma")


class ConfigError(ValueError):
    """An invalid configuration value; the message names the field and the allowed range."""


def field_values(cfg) -> dict:
    """Every field of ``cfg`` checked against the bounds table (``smjax.train.bounds``),
    numpy scalars as Python numbers, a true or false ``finetune`` as "on" or "off"."""
    try:
        values = checked_fields({f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)})
    except BoundsError as err:
        raise ConfigError(str(err)) from None
    if isinstance(values["finetune"], bool):  # YAML 1.1 reads ``finetune: off`` as false
        values["finetune"] = "on" if values["finetune"] else "off"
    return values


def check_fields(cfg) -> None:
    """The choices, types and cross-field rules of one config (its ``levels`` overrides
    aside: ``level_configs`` checks those)."""
    def need(ok: bool, name: str, allowed: str) -> None:
        if not ok:
            raise ConfigError(f"config field {name!r} = {short(getattr(cfg, name))}: must "
                              f"be {allowed}")

    need(cfg.method in METHODS, "method", f"one of {METHODS}")
    need(cfg.algo in ALGOS, "algo", f"one of {ALGOS}")
    need(cfg.hierarchy is None or isinstance(cfg.hierarchy, str), "hierarchy", "a name or None")
    need(cfg.policy_memory in POLICY_MEMORIES, "policy_memory", f"one of {POLICY_MEMORIES}")
    need(cfg.frozen_eval in ("auto", "learned", "all"), "frozen_eval",
         "one of ('auto', 'learned', 'all')")
    need(cfg.finetune in FINETUNE_CHOICES, "finetune", f"one of {FINETUNE_CHOICES}")
    need(cfg.finetune_mode in FINETUNE_MODES, "finetune_mode", f"one of {FINETUNE_MODES}")
    need(cfg.frozen_policy in FROZEN_POLICIES, "frozen_policy", f"one of {FROZEN_POLICIES}")
    need(cfg.eval_policies in EVAL_POLICIES, "eval_policies", f"one of {EVAL_POLICIES}")
    for name in ("tensorboard", "continue_episodes", "gate", "finetune_side_cost",
                 "finetune_continue_episodes"):
        need(isinstance(getattr(cfg, name), bool), name, "true or false")
    need(isinstance(cfg.agent, dict), "agent", "a mapping of learner hyper-parameters")
    need(isinstance(cfg.finetune_agent, dict) and all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
        and math.isfinite(v) for k, v in cfg.finetune_agent.items()),
         "finetune_agent", "a mapping of learner hyper-parameter names (or update settings: "
         "update_epochs, num_minibatches) to numbers")
    if "gamma" in cfg.agent:  # one source: the trainer discounts with TrainConfig.gamma
        raise ConfigError(f"agent field 'gamma' = {cfg.agent['gamma']!r} would be ignored: the "
                          f"discount is the config field 'gamma'; set it with --set gamma=X "
                          f"(TrainConfig(gamma=X))")
    check_learner(cfg)
    need(isinstance(cfg.levels, dict) and all(isinstance(k, str) and isinstance(v, dict)
                                              for k, v in cfg.levels.items()),
         "levels", "a mapping of template name -> {field: value}")
    if cfg.success_window > cfg.max_episodes_per_level:
        raise ConfigError(
            f"config field 'success_window' = {cfg.success_window} exceeds "
            f"'max_episodes_per_level' = {cfg.max_episodes_per_level}: the running success "
            f"would never fill its window within the level's episode budget, so the threshold "
            f"could never be reached; lower success_window (--set success_window=N) or raise "
            f"max_episodes_per_level")


def level_configs(cfg) -> dict:
    """Per template of ``cfg.levels``: ``cfg`` with that template's overrides, checked (its
    values, and its window against its budget) as a config of its own."""
    out = {}
    for name, fields in cfg.levels.items():
        unknown = sorted(set(fields) - set(LEVEL_FIELDS), key=repr)
        if unknown:
            raise ConfigError(f"config field 'levels' for template {name!r}: unknown field(s) "
                              f"{unknown}; per-level fields: {list(LEVEL_FIELDS)}")
        try:
            out[name] = dataclasses.replace(cfg, levels={}, **fields)
        except ConfigError as err:
            raise ConfigError(f"config field 'levels' for template {name!r}: {err} (set both "
                              f"in levels[{name!r}] if only this level differs)") from None
    return out


def check_learner(cfg) -> None:
    """The learner's fields (unknown ones too), the fine-tuning overrides on top of them,
    and what the run's batch bounds (``bounds.check_agent``)."""
    from smjax.agents import make_config

    if cfg.algo not in ALGOS:
        return
    try:
        agent = normalize_agent(cfg.algo, cfg.agent)
        config = make_config(cfg.algo, **agent)
        check_agent(config, cfg.num_envs, cfg.rollout_ticks)
    except (ValueError, TypeError) as err:
        raise ConfigError(short_message(str(err))) from None
    tuning = normalize_agent(cfg.algo, cfg.finetune_agent)
    try:
        # a learning rate of 0 freezes what fine-tuning would move: allowed here alone
        if tuning.get("learning_rate") == 0 and not isinstance(tuning["learning_rate"], bool):
            tuning = tuning | {"learning_rate": agent.get("learning_rate", 1e-3)}
        check_agent(make_config(cfg.algo, **(agent | tuning)), cfg.num_envs, cfg.rollout_ticks)
    except (ValueError, TypeError) as err:
        raise ConfigError(short_message(f"config field 'finetune_agent': {err}")) from None


def parsed_fields(cls, data: dict) -> dict:
    """``data`` with scalar values parsed by the type of the field's default."""
    from smjax.core.overrides import coerce_like

    defaults = {f.name: f.default for f in dataclasses.fields(cls)
                if f.default is not dataclasses.MISSING}
    out = dict(data)
    try:
        for name, value in data.items():
            if name in defaults and defaults[name] is not None:
                out[name] = coerce_like(f"config field {name!r}", value, defaults[name])
        if isinstance(out.get("agent"), dict):
            out["agent"] = normalize_agent(out.get("algo", cls.algo), out["agent"])
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return out


def normalize_agent(algo: Any, agent: dict) -> dict:
    """Learner overrides parsed by the type of the learner config's field (``"no"`` -> False,
    ``(32, 32)`` -> [32, 32], as JSON stores it, so a resumed run compares equal)."""
    from smjax.core.overrides import coerce_like

    if algo not in ALGOS:
        return dict(agent)  # check_fields names the bad algo
    from smjax.agents import default_config

    defaults = dataclasses.asdict(default_config(algo))
    out = {}
    for name, value in agent.items():
        if name in defaults:
            value = coerce_like(f"agent field {name!r}", value, defaults[name])
        out[name] = list(value) if isinstance(value, tuple) else value
    return out
