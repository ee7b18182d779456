"""Typed training configuration, validated before anything compiles."""
from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from smjax.options.memory import POLICY_MEMORIES
from smjax.train.bounds import (BoundsError, check_agent, checked_fields, short, short_message,
                                strict_json, strict_yaml)

METHODS = ("top-down", "bottom-up", "flat")
ALGOS = ("ppo", "dqn", "actor-critic")
FROZEN_POLICIES = ("auto", "greedy", "sample")
FINETUNE_CHOICES = ("auto", "on", "off")
FINETUNE_MODES = ("turns", "joint")
# what ``TrainConfig.levels`` may override per template
LEVEL_FIELDS = ("threshold", "max_episodes_per_level", "max_steps_per_level", "success_window",
                "gamma")


class ConfigError(ValueError):
    """An invalid configuration value; the message names the field and the allowed range."""


@dataclass(frozen=True)
class TrainConfig:
    """Every knob of a training run (docs/guide.md, "TrainConfig reference").

    Attributes:
      method: top-down (the paper's Algorithms 1-2), bottom-up (sub-skills first, from
        reset states) or flat (one learner over the hierarchy's leaves).
      algo: the learner of every level: ppo, dqn or actor-critic (the paper's).
      hierarchy: a name from ``env.hierarchies()``; None: the catalogue's first.
      num_envs: parallel environments per seed.
      rollout_ticks: ticks per rollout (one learner update per rollout).
      updates_per_chunk: rollouts per compiled chunk (the host checks progress between chunks).
      threshold: the running success that ends a level (0.8: the paper's).
      ceiling_fraction: a root threshold at or above the task's best success
        (``Hierarchy.success_ceiling``) is lowered to this fraction of it, since only a
        perfect exploring policy could reach it; the effective ``levels`` records it.
      success_window: learner episodes the running success averages (at most the level's
        episode budget, or it could never fill).
      max_episodes_per_level: a level's budget in environment episodes.
      max_steps_per_level: a second budget in env steps (0: none); the first met ends the
        level. Env-step budgets compare methods fairly when episode lengths differ.
      levels: per-template overrides of ``LEVEL_FIELDS``, e.g. ``{"attack": {"threshold":
        0.3}}``; a level's ``gamma`` is its learner's discount, in its level and in
        fine-tuning, and wins over a swept gamma.
      gamma: discount per primitive tick (gamma**d for a teleported call of duration d).
      frozen_policy: how frozen options act (auto: greedy for dqn, else sample).
      option_temperature: where frozen policies sample, the temperature of every template
        below the root (the root samples at 1).
      continue_episodes: do not reset when the trained option ends, so it also trains on
        the states the full task gives it (off: reset, as the paper does).
      gate: a level ends only when the policy that will be frozen passes on fresh episodes
        too: the running success of an exploring policy can pass by luck.
      gate_envs: episodes of one gate attempt (one per environment).
      gate_max_ticks: cap on a gate episode (an unfinished one fails).
      gate_interval: chunks between a seed's gate attempts.
      eval_envs: episodes (one per environment) that measure final_success.
      eval_max_ticks: cap on an evaluation episode.
      tensorboard: also write TensorBoard event files to OUT/tensorboard.
      reset_pool: episode starts generated ahead of each rollout, per seed (None:
        ``num_envs``; 0: a fresh start per environment per tick, exact but slow where
        generating a world costs as much as a step).
      frozen_eval: how a tick runs the frozen policies: "learned" (only the learned options,
        one after another: cheaper on a CPU), "all" (one batched apply: cheaper on a GPU),
        "auto" (by backend). The results are the same.
      policy_memory: "none", or "last_action": the last primitive action and whether it
        changed the observation, so a policy can tell a blocked move from a new state.
      finetune: after the levels, fine-tune the learned hierarchy without teleports: "on",
        "off" or "auto" (on for top-down, whose levels learn with help above and below).
      finetune_mode: "joint" (every option learns from its own decisions in every episode:
        more data per option than turns give) or "turns" (one option at a time).
      finetune_threshold: the teleport-free task success whose gate ends the phase (0.92: the
        gate stops on a high draw, so the margin keeps the final evaluation at 0.9 or above).
      finetune_option_threshold: turns: an option's running success that ends its turn.
      finetune_max_rest: turns: turns in a row a converged option may sit out (0: none).
      finetune_turn_episodes: turns: episodes of one turn at most (250: about one chunk, so
        every option improves a little in each round).
      finetune_continue_episodes: turns: episodes in flight go on into the next turn, so the
        longest episodes are finished and counted rather than cut off.
      finetune_max_episodes: the phase's episode budget per seed.
      finetune_plateau_episodes: the phase also ends when a block of this many episodes
        gains less than ``finetune_plateau_gain`` over the one before (0: never); 4,000
        averages out the noise while a slow climb still counts.
      finetune_plateau_gain: the least rise of a block's mean that counts as climbing;
        at 0.02 get_gem stops ~3,000 episodes sooner than at 0.01 for ~0.005 of success.
      finetune_agent: learner hyper-parameters used in fine-tuning instead of ``agent``'s;
        only traced leaves (the sweepable ones), so the phase compiles nothing new.
      finetune_side_cost: in fine-tuning, a template learner is also rewarded by the
        decrease of its template's ``side_cost`` (Craft: items held beyond the promise).
      finetune_side_cost_weight: the side cost's weight (1: as the templates declare it).
      level_side_cost_weight: the same shaping while the levels train (0: off).
      checkpoint_every: seconds between checkpoints with an output directory (0: every
        chunk); a checkpoint is also written when a level or turn ends (ends close
        together share one write: ``smjax.train.hooks.CheckpointHook``).
    """

    method: str = "top-down"
    algo: str = "ppo"
    hierarchy: str | None = None
    num_envs: int = 128
    rollout_ticks: int = 32
    updates_per_chunk: int = 4
    threshold: float = 0.8
    ceiling_fraction: float = 0.9
    success_window: int = 256
    max_episodes_per_level: int = 40_000
    max_steps_per_level: int = 0
    gamma: float = 0.99
    frozen_policy: str = "auto"
    option_temperature: float = 1.0
    continue_episodes: bool = False
    gate: bool = True
    gate_envs: int = 256
    gate_max_ticks: int = 2000
    gate_interval: int = 8
    eval_envs: int = 256
    eval_max_ticks: int = 2000
    reset_pool: int | None = None
    frozen_eval: str = "auto"
    policy_memory: str = "none"
    finetune: str = "auto"
    finetune_mode: str = "joint"
    finetune_threshold: float = 0.92
    finetune_option_threshold: float = 0.95
    finetune_turn_episodes: int = 250
    finetune_max_rest: int = 0
    finetune_continue_episodes: bool = True
    finetune_max_episodes: int = 20_000
    finetune_plateau_episodes: int = 4000
    finetune_plateau_gain: float = 0.02
    finetune_agent: dict = field(default_factory=dict)
    finetune_side_cost: bool = True
    finetune_side_cost_weight: float = 1.0
    level_side_cost_weight: float = 0.0
    checkpoint_every: float = 60.0
    tensorboard: bool = False
    agent: dict = field(default_factory=dict)
    levels: dict = field(default_factory=dict)

    def __post_init__(self):
        try:  # numpy scalars become Python numbers; every bound is in one table
            values = checked_fields({f.name: getattr(self, f.name) for f in dataclasses.fields(self)})
        except BoundsError as err:
            raise ConfigError(str(err)) from None
        for name, value in values.items():
            object.__setattr__(self, name, value)
        self.validate()

    def validate(self) -> None:
        def need(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ConfigError(f"config field {name!r} = {short(getattr(self, name))}: must "
                                  f"be {allowed}")

        try:
            checked_fields({f.name: getattr(self, f.name) for f in dataclasses.fields(self)})
        except BoundsError as err:
            raise ConfigError(str(err)) from None
        need(self.method in METHODS, "method", f"one of {METHODS}")
        need(self.algo in ALGOS, "algo", f"one of {ALGOS}")
        need(self.hierarchy is None or isinstance(self.hierarchy, str), "hierarchy", "a name or None")
        need(self.policy_memory in POLICY_MEMORIES, "policy_memory", f"one of {POLICY_MEMORIES}")
        need(self.frozen_eval in ("auto", "learned", "all"), "frozen_eval",
             "one of ('auto', 'learned', 'all')")
        need(self.finetune in FINETUNE_CHOICES, "finetune", f"one of {FINETUNE_CHOICES}")
        need(self.finetune_mode in FINETUNE_MODES, "finetune_mode", f"one of {FINETUNE_MODES}")
        need(self.frozen_policy in FROZEN_POLICIES, "frozen_policy", f"one of {FROZEN_POLICIES}")
        need(isinstance(self.tensorboard, bool), "tensorboard", "true or false")
        need(isinstance(self.continue_episodes, bool), "continue_episodes", "true or false")
        need(isinstance(self.gate, bool), "gate", "true or false")
        need(isinstance(self.finetune_side_cost, bool), "finetune_side_cost", "true or false")
        need(isinstance(self.finetune_continue_episodes, bool), "finetune_continue_episodes",
             "true or false")
        need(isinstance(self.agent, dict), "agent", "a mapping of learner hyper-parameters")
        need(isinstance(self.finetune_agent, dict) and all(
            isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
            and math.isfinite(v) for k, v in self.finetune_agent.items()),
             "finetune_agent", "a mapping of learner hyper-parameter names to numbers")
        if "gamma" in self.agent:  # one source: the trainer discounts with TrainConfig.gamma
            raise ConfigError(f"agent field 'gamma' = {self.agent['gamma']!r} would be ignored: the "
                              f"discount is the config field 'gamma'; set it with --set gamma=X "
                              f"(TrainConfig(gamma=X))")
        self._check_agent()
        need(isinstance(self.levels, dict) and all(isinstance(k, str) and isinstance(v, dict)
                                                   for k, v in self.levels.items()),
             "levels", "a mapping of template name -> {field: value}")
        if self.success_window > self.max_episodes_per_level:
            raise ConfigError(
                f"config field 'success_window' = {self.success_window} exceeds "
                f"'max_episodes_per_level' = {self.max_episodes_per_level}: the running success "
                f"would never fill its window within the level's episode budget, so the threshold "
                f"could never be reached; lower success_window (--set success_window=N) or raise "
                f"max_episodes_per_level")
        for name, fields in self.levels.items():
            unknown = sorted(set(fields) - set(LEVEL_FIELDS), key=repr)
            if unknown:
                raise ConfigError(f"config field 'levels' for template {name!r}: unknown field(s) "
                                  f"{unknown}; per-level fields: {list(LEVEL_FIELDS)}")
            try:  # validates the override values, and the level's window against its budget
                dataclasses.replace(self, levels={}, **fields)
            except ConfigError as err:
                raise ConfigError(f"config field 'levels' for template {name!r}: {err} (set both "
                                  f"in levels[{name!r}] if only this level differs)") from None

    def _check_agent(self) -> None:
        """The learner's fields (unknown ones too), the fine-tuning overrides on top of them,
        and what the run's batch bounds (``bounds.check_agent``)."""
        from smjax.agents import make_config

        if self.algo not in ALGOS:
            return
        try:
            agent = normalize_agent(self.algo, self.agent)
            config = make_config(self.algo, **agent)
            check_agent(config, self.num_envs, self.rollout_ticks)
        except (ValueError, TypeError) as err:
            raise ConfigError(short_message(str(err))) from None
        tuning = normalize_agent(self.algo, self.finetune_agent)
        try:
            # a learning rate of 0 freezes what fine-tuning would move: allowed here alone
            if tuning.get("learning_rate") == 0 and not isinstance(tuning["learning_rate"], bool):
                tuning = tuning | {"learning_rate": agent.get("learning_rate", 1e-3)}
            make_config(self.algo, **(agent | tuning))
        except (ValueError, TypeError) as err:
            raise ConfigError(short_message(f"config field 'finetune_agent': {err}")) from None

    @property
    def finetune_on(self) -> bool:
        """Whether the fine-tuning phase runs ("auto": for top-down)."""
        return self.finetune == "on" or (self.finetune == "auto" and self.method == "top-down")

    @property
    def pool_size(self) -> int:
        """Episode starts per rollout (``reset_pool`` resolved; 0: none, reset every tick)."""
        return self.num_envs if self.reset_pool is None else self.reset_pool

    @property
    def window_slots(self) -> int:
        """Batches a running-success window keeps on the device: the largest
        ``success_window`` of any level (each kept batch holds at least one episode)."""
        return max([self.success_window] + [int(v.get("success_window", 0))
                                            for v in self.levels.values()])

    def for_level(self, template: str) -> "TrainConfig":
        """The config a level trains with: this one plus ``levels[template]``'s overrides."""
        return dataclasses.replace(self, levels={}, **self.levels.get(template, {}))

    def check_level_names(self, names) -> None:
        """Refuse overrides for templates the run does not train (a typo would be silent)."""
        unknown = sorted(set(self.levels) - set(names))
        if unknown:
            raise ConfigError(f"config field 'levels' names {unknown}, which this run does not "
                              f"train; trained templates: {list(names)}")

    def replace(self, **changes: Any) -> "TrainConfig":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        """A config from a mapping, values parsed strictly by each field's type (``"no"`` is
        False, ``16.0`` is 16, ``2.5`` for an integer field and NaN are refused)."""
        if not isinstance(data, dict):
            raise ConfigError(f"a config must be a mapping of fields, got {type(data).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names, key=repr)  # key=repr: keys may be of any type
        if unknown:
            close = [m for u in unknown if isinstance(u, str)
                     for m in difflib.get_close_matches(u, names, n=1)]
            maybe = f" Did you mean {', '.join(repr(m) for m in close)}?" if close else ""
            raise ConfigError(f"unknown config field(s) {short(unknown)}.{maybe} Valid fields: "
                              f"{sorted(names)}")
        return cls(**_parsed_fields(cls, data))

    @classmethod
    def from_file(cls, path: str | Path) -> "TrainConfig":
        return cls.from_dict(read_config_file(path))


# settings that do not change what a run computes: not part of a run's identity, so a
# resume may change them (the output directory and progress bars are not config fields)
RUN_SETTINGS = ("tensorboard", "checkpoint_every")


def resolve_config(base: TrainConfig | None = None, *, saved_run: dict | None = None,
                   file: str | Path | None = None, sets: dict | None = None,
                   agent: dict | None = None) -> TrainConfig:
    """The one place a run's configuration is assembled (``smjax train`` and ``run`` call
    it). Later sources override
    earlier ones: ``base`` (a config, else the defaults), the fields a saved run recorded
    (``saved_run``: a checkpoint's run identity; its other keys are ignored), the fields a
    ``file`` sets, ``sets`` (field -> value), and ``agent``, merged into the learner's
    hyper-parameters. Values from the sources are parsed strictly by each field's type and
    the learner's overrides normalised as JSON stores them, so a resumed run compares
    equal to its checkpoint."""
    names = set(TrainConfig.__dataclass_fields__)
    data = {k: v for k, v in (saved_run or {}).items() if k in names}
    if file is not None:
        data.update(read_config_file(file))  # only the fields the file sets
    data.update(sets or {})
    if agent:
        if "gamma" in agent:
            raise ConfigError(f"--agent gamma={agent['gamma']} would be ignored: the discount is "
                              f"a training setting; use --set gamma={agent['gamma']}")
        data["agent"] = dict(data.get("agent", base.agent if base is not None else {})) | agent
    if base is None:
        cfg = TrainConfig.from_dict(data)
    elif data:
        cfg = TrainConfig.from_dict(base.to_dict() | data)
    else:
        cfg = base
    return cfg.replace(agent=normalize_agent(cfg.algo, cfg.agent))


def read_config_file(path: str | Path) -> dict:
    """The fields a YAML/JSON config file sets (validated; defaults not filled in, so a
    resume is refused only for fields the file really sets)."""
    path = Path(path)
    import yaml

    if not path.is_file():
        what = "is a directory" if path.is_dir() else "does not exist"
        raise ConfigError(f"config file {path} {what}; pass a YAML or JSON file of TrainConfig fields")
    try:  # undecodable bytes and syntax errors become one error type naming the file
        text = path.read_text()
        data = strict_yaml(text) if path.suffix in (".yaml", ".yml") else strict_json(text)
    except (OSError, ValueError, yaml.YAMLError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ConfigError(f"config file {path} cannot be read or parsed: {first}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config file {path} must hold a mapping of fields, got "
                          f"{type(data).__name__}")
    try:
        TrainConfig.from_dict(data)
    except (ConfigError, TypeError, ValueError) as err:
        raise ConfigError(f"config file {path}: {err}") from None
    return _parsed_fields(TrainConfig, data)


def _parsed_fields(cls, data: dict) -> dict:
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
        return dict(agent)  # validate() names the bad algo
    from smjax.agents import default_config

    defaults = dataclasses.asdict(default_config(algo))
    out = {}
    for name, value in agent.items():
        if name in defaults:
            value = coerce_like(f"agent field {name!r}", value, defaults[name])
        out[name] = list(value) if isinstance(value, tuple) else value
    return out


def config_differences(a: dict, b: dict) -> list[str]:
    """Field names whose values differ between two config dicts (for resume checks)."""
    keys = sorted(set(a) | set(b))
    return [k for k in keys if a.get(k) != b.get(k)]
