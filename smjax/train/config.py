"""Typed training configuration, validated before anything compiles."""
from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from smjax.agents.config import traced
from smjax.train.bounds import short, strict_json, strict_yaml
from smjax.train.config_checks import (  # noqa: F401 - re-exported: the config's vocabulary
    ALGOS, FINETUNE_CHOICES, FINETUNE_MODES, FROZEN_POLICIES, LEVEL_FIELDS, METHODS, ConfigError,
    check_fields, field_values, level_configs, normalize_agent, parsed_fields,
)
from smjax.train.sections import Evaluation, FineTuning, Run, SectionError, flatten_sections


@dataclass(frozen=True)
class LevelSettings:
    """What one level trains with: the config's ``LEVEL_FIELDS``, with that level's
    ``levels`` overrides applied (``gamma``: the level's own discount, else the config's;
    a sweep's per-slot discount gives way to a level's own: ``smjax.train.slots``)."""

    threshold: float
    max_episodes_per_level: int
    max_steps_per_level: int
    success_window: int
    gamma: float

    @classmethod
    def of(cls, cfg) -> "LevelSettings":
        return cls(**{name: getattr(cfg, name) for name in LEVEL_FIELDS})


@dataclass(frozen=True)
class TrainConfig:
    """Every knob of a training run (docs/guide.md, "TrainConfig reference").

    The parts of training read it in typed sections, resolved once when it is made:
    ``run`` (the rollout's shape, the runner's structure, checkpoints and TensorBoard),
    ``fine_tuning`` (``finetune*`` fields), ``evaluation`` (``gate*``, ``eval_*``) and
    ``for_level(name)``; files and ``--set`` may name fields by section
    (``fine_tuning.threshold``, ``run.num_envs``: :mod:`smjax.train.sections`).

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
      gamma: discount per primitive tick (gamma**d for a teleported call of duration d);
        traced (a per-slot value of the training chunk), so a sweep may vary it.
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
      eval_policies: "run": the final evaluation under the run's ``frozen_policy`` alone;
        "all": also under every other mode (``final_success_by_policy``), 4x its time.
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
      finetune_plateau_gain: the least rise of a block's mean that counts as climbing; a
        larger gain ends the phase sooner, at a small cost in final success.
      finetune_agent: learner hyper-parameters used in fine-tuning instead of ``agent``'s
        (traced leaves, the sweepable ones: the phase compiles nothing new), and in joint
        fine-tuning the update's settings (PPO's update_epochs, num_minibatches): its
        update is then built with them, from the same learners.
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
    gamma: float = traced(0.99)
    frozen_policy: str = "auto"
    option_temperature: float = 1.0
    continue_episodes: bool = False
    gate: bool = True
    gate_envs: int = 256
    gate_max_ticks: int = 2000
    gate_interval: int = 8
    eval_envs: int = 256
    eval_max_ticks: int = 2000
    eval_policies: str = "run"
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
        for name, value in field_values(self).items():  # numpy scalars become Python numbers
            object.__setattr__(self, name, value)
        check_fields(self)
        # every level's settings are checked and resolved here, once: a frozen config
        # cannot change, so ``for_level`` only looks them up
        levels = {name: LevelSettings.of(c) for name, c in level_configs(self).items()}
        object.__setattr__(self, "_level_settings", (LevelSettings.of(self), levels))
        # the learner's overrides as JSON stores them, so a resumed run compares equal
        object.__setattr__(self, "agent", normalize_agent(self.algo, self.agent))
        object.__setattr__(self, "_sections",
                           (FineTuning.of(self), Evaluation.of(self), Run.of(self)))

    @property
    def fine_tuning(self) -> FineTuning:
        """The fine-tuning phase's section (``finetune*`` fields; ``on`` resolved)."""
        return self._sections[0]

    @property
    def evaluation(self) -> Evaluation:
        """The gate's and the final evaluation's section."""
        return self._sections[1]

    @property
    def run(self) -> Run:
        """How the ticks run and what the run writes beside its results."""
        return self._sections[2]

    @property
    def window_slots(self) -> int:
        """Batches a running-success window keeps on the device: the largest
        ``success_window`` of any level (each kept batch holds at least one episode)."""
        return max([self.success_window] + [level.success_window
                                            for level in self._level_settings[1].values()])

    def for_level(self, template: str) -> LevelSettings:
        """The settings level ``template`` trains with: the config's, plus
        ``levels[template]``'s overrides."""
        base, levels = self._level_settings
        return levels.get(template, base)

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
        data = flat_fields(data)
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names, key=repr)  # key=repr: keys may be of any type
        if unknown:
            close = [m for u in unknown if isinstance(u, str)
                     for m in difflib.get_close_matches(u, names, n=1)]
            maybe = f" Did you mean {', '.join(repr(m) for m in close)}?" if close else ""
            raise ConfigError(f"unknown config field(s) {short(unknown)}.{maybe} Valid fields: "
                              f"{sorted(names)}")
        return cls(**parsed_fields(cls, data))

    @classmethod
    def from_file(cls, path: str | Path) -> "TrainConfig":
        return cls.from_dict(read_config_file(path))


# settings that do not change what a run computes: not part of a run's identity, so a
# resume may change them (the output directory and progress bars are not config fields)
RUN_SETTINGS = ("tensorboard", "checkpoint_every")

# fields no compiled program depends on: the host reads them between chunks (budgets,
# thresholds, stopping rules, how often to gate, what to evaluate), or the programs take them
# as inputs (the episodes' tick caps, a seed's side cost and whether its episodes go on). A
# run that differs from an earlier one only in these loads that run's saved programs
# untraced (smjax.train.program_cache); tests/test_program_identity.py checks that changing
# all of them leaves every saved program's text as it was.
OUTSIDE_PROGRAMS = RUN_SETTINGS + (
    "threshold", "ceiling_fraction", "max_episodes_per_level", "max_steps_per_level",
    "gate_interval", "gate_max_ticks", "eval_max_ticks", "eval_policies", "continue_episodes",
    "level_side_cost_weight", "finetune_threshold", "finetune_option_threshold",
    "finetune_turn_episodes", "finetune_max_rest", "finetune_continue_episodes",
    "finetune_max_episodes", "finetune_plateau_episodes", "finetune_plateau_gain",
    "finetune_side_cost_weight")


def program_config(cfg: TrainConfig) -> dict:
    """``cfg.to_dict()`` without ``OUTSIDE_PROGRAMS``, in ``levels`` too: what a run's
    compiled programs depend on of its config."""
    fields = {k: v for k, v in cfg.to_dict().items() if k not in OUTSIDE_PROGRAMS}
    levels = {name: {k: v for k, v in level.items() if k not in OUTSIDE_PROGRAMS}
              for name, level in fields.get("levels", {}).items()}
    fields["levels"] = {name: level for name, level in levels.items() if level}
    return fields


def resolve_config(base: TrainConfig | None = None, *, saved_run: dict | None = None,
                   file: str | Path | None = None, sets: dict | None = None,
                   agent: dict | None = None) -> TrainConfig:
    """The one place a run's configuration is assembled from its sources (``smjax train``
    calls it; ``run`` takes its result, or any ``TrainConfig``). Later sources override
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
    data.update(flat_fields(sets or {}))
    if agent:
        if "gamma" in agent:
            raise ConfigError(f"--agent gamma={agent['gamma']} would be ignored: the discount is "
                              f"a training setting; use --set gamma={agent['gamma']}")
        data["agent"] = dict(data.get("agent", base.agent if base is not None else {})) | agent
    if base is None:
        return TrainConfig.from_dict(data)
    # (a config normalises its learner's overrides when it is made: ``base`` already has)
    return TrainConfig.from_dict(base.to_dict() | data) if data else base


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
        data = flat_fields(data)
        TrainConfig.from_dict(data)
    except (ConfigError, TypeError, ValueError) as err:
        raise ConfigError(f"config file {path}: {err}") from None
    return parsed_fields(TrainConfig, data)


def flat_fields(data: dict) -> dict:
    """``data`` with fields named by section (``fine_tuning.threshold``) as flat fields."""
    try:
        return flatten_sections(data)
    except SectionError as err:
        raise ConfigError(str(err)) from None


def config_differences(a: dict, b: dict) -> list[str]:
    """Field names whose values differ between two config dicts (for resume checks)."""
    keys = sorted(set(a) | set(b))
    return [k for k in keys if a.get(k) != b.get(k)]
