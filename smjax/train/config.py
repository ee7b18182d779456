"""Typed training configuration, validated before anything compiles."""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from smjax.options.memory import POLICY_MEMORIES

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
    """Every knob of a training run. ``agent`` holds the learner's own hyper-parameters.

    Attributes:
      method: top-down (the paper's Algorithms 1-2), bottom-up (option-value iteration
        order: sub-skills first from reset states), or flat (one learner, no hierarchy).
      algo: learner for every level: ppo, dqn or actor-critic (the paper's).
      hierarchy: name from ``env.hierarchies()``; None picks the environment's default
        (the first of its catalogue). ``flat`` trains its flattening (one level over its
        leaves: ``Hierarchy.flattened``).
      num_envs: parallel environments per seed.
      rollout_ticks: ticks per rollout (one learner update per rollout).
      updates_per_chunk: rollouts per compiled chunk (the host checks progress between chunks).
      threshold: a level ends when its running success reaches this (the paper: 0.8).
      ceiling_fraction: where the root level's threshold is at or above the best task
        success an episode can reach (``Hierarchy.success_ceiling``; Craft's make_bench:
        0.8), the level ends at this fraction of that best instead (0.9: as far below it
        as get_gem's 0.8 is below its 0.9); such a threshold could only be met with every
        exploring episode perfect, and the level would spend its whole budget. The lowered
        threshold is written into ``levels`` (the effective config shows it).
      success_window: number of recent learner episodes the running success averages; at
        most ``max_episodes_per_level`` (a longer window could never fill, so the threshold
        could never be reached), per level too.
      max_episodes_per_level: the level's budget L (environment episodes).
      max_steps_per_level: a second budget in environment steps (0: none); a level ends at
        whichever budget it meets first. Env-step budgets compare methods fairly when
        episodes differ in length (football games, Fetch).
      levels: per-template overrides, e.g. ``{"attack": {"threshold": 0.3,
        "max_steps_per_level": 1_500_000}}``; keys are template names of the hierarchy
        (checked when training starts) and values override ``LEVEL_FIELDS``. A level's
        ``gamma`` is that learner's discount, in its level and in its fine-tuning turns,
        and wins over a swept gamma.
      gamma: discount per primitive tick (gamma**d for a teleported call of duration d).
      frozen_policy: how trained options act when frozen (auto: greedy for dqn, else sample).
      option_temperature: where frozen policies sample, the temperature every template
        below the root samples at (the root samples at 1), in the levels, gates,
        fine-tuning and the final evaluation; below 1 a template takes its likelier
        actions more often (fewer stray ones) while the root keeps its randomness.
      continue_episodes: top-down/bottom-up only: do not reset the environment when the
        option being trained ends; its next episode starts wherever the frozen levels above
        call it again, i.e. on the states the full task gives it (football's ``attack`` is
        otherwise only trained from kick-offs). Default: reset, as the paper does.
      gate: a level ends only when the policy that will be frozen passes too. Once a
        seed's running success (of the exploring behaviour policy) reaches the threshold,
        ``gate_envs`` fresh episodes run with the learner acting as it will in the policy
        bank (greedy for dqn), called from reset states by the trained levels above; the
        level ends if their success reaches the threshold, else training goes on and the
        gate is tried again ``gate_interval`` chunks later. Without it a DQN level can end
        on exploration luck (RESULTS section 7). Gate episodes train nothing and are
        reported per level as ``gate_env_steps``, apart from the training counts.
      gate_envs: episodes of one gate attempt (one per environment).
      gate_max_ticks: cap on a gate attempt's length (an unfinished episode fails).
      gate_interval: chunks between a seed's gate attempts.
      eval_envs: episodes run (one per environment) to measure final_success.
      eval_max_ticks: cap on an evaluation episode's length.
      tensorboard: also write TensorBoard event files (OUT/tensorboard) of every level's
        running success and episode count per seed.
      reset_pool: episode starts generated ahead of each rollout, per seed; an environment
        whose episode ends takes the next unused one (reused only when more episodes than
        this end in one rollout). None: ``num_envs``. 0: generate a fresh start for every
        environment in every tick and keep it where an episode ended (the exact but slow
        way: the generation costs as much as a step in procedurally generated worlds).
      frozen_eval: how a tick evaluates the frozen policies: "learned" (only the learned
        options that can decide, one after another: on a CPU most of the bank is not
        learned yet and a wide first layer is the tick's largest cost), "all" (the whole
        bank in one batched apply: cheaper on a GPU, where launches cost more than FLOPs),
        "auto" (learned on a CPU, all elsewhere). The results are the same either way.
      policy_memory: what the policies see besides the observation: "none", or
        "last_action" (the last primitive action and whether it changed the observation,
        smjax.options.memory): a policy can then tell a blocked move from a new state
        without sampling its way out (networks and checkpoints are shaped by it).
      finetune: after the levels, fine-tune the learned hierarchy without teleports:
        "on", "off", or "auto" (on for top-down, the method whose levels learn with
        teleports above and below them). The learned options keep learning, warm-started
        from their frozen policies, in whole-task episodes of the learned hierarchy alone
        (scripted leaf controllers still run), each on its own decisions with its own
        reward (``finetune_mode`` says whether all at once or in turns). A seed whose
        levels' hierarchy already passes the gate at ``finetune_threshold`` (the evaluation
        before the phase is its first attempt) skips the phase. The phase ends
        when the teleport-free task success passes a gate at ``finetune_threshold``, when
        it stops climbing (``finetune_plateau_episodes``) or after
        ``finetune_max_episodes`` (docs/guide.md, "Fine-tuning").
      finetune_mode: "joint" (every learned option explores through its own learner and
        learns from its own decisions in every episode) or "turns" (one option learns at
        a time while the others act frozen; a turn ends when the option's own running
        success reaches ``finetune_option_threshold`` or after
        ``finetune_turn_episodes``). Joint is the default because it measured better on
        every Craft task at the same budget, the option gets every episode's decisions
        instead of a turn's share (get_gem 0.843 against 0.766, get_gold 0.93 in ~14,000
        episodes in all against 0.895 in ~24,500: benchmarks/RESULTS.md section 19). With
        a learner that trains every option at once (``Agent.update_options``: PPO) an
        update costs about one learner's update on the rollout's decisions; otherwise one
        learner update per option. Not with a recurrent policy.
      finetune_threshold: the teleport-free task success the phase stops at (0.92: a gate
        stops on the first draw that reaches it, a high one, so a final evaluation after
        a pass at 0.9 landed below 0.9; the margin keeps it at or above).
      finetune_option_threshold: turns: an option's running success (where the learned
        hierarchy calls it) that ends its turn early.
      finetune_max_rest: turns in a row an option may sit out while it is converged: an
        option whose last turn ended at ``finetune_option_threshold`` or above passes its
        next turns to the others, up to this many in a row, then plays again to check that
        it still holds where the hierarchy calls it (0, the default: every option plays
        every round). Measured neutral: at 3 the root gets twice the turns, yet get_gem's
        and get_gold's task success climbs no faster per episode (RESULTS section 14).
      finetune_turn_episodes: environment episodes of one option's turn at most (250:
        about one chunk; short turns let every option improve a little in each round, and
        reached in 6,000-8,000 episodes what turns of 2,000 reached in 20,000:
        benchmarks/RESULTS.md section 13).
      finetune_continue_episodes: episodes in flight when a turn ends go on into the next
        turn (only the learner changes hands: its pending decision and episode record start
        afresh). Off, every turn started all environments on fresh episodes, so each turn's
        longest episodes (the failing ones, ~1 in 3 of a 250-episode turn over 128
        environments) were cut off unfinished: no option learned how they end, and the
        phase's running success, counting finished episodes only, read ~0.05 above a
        fresh evaluation (benchmarks/RESULTS.md section 18).
      finetune_max_episodes: the phase's budget in environment episodes, per seed (at
        12,000, get_gem's and get_gold's totals with the levels stay under 21,000 and
        19,000 episodes, and their final success is 0.03-0.04 lower: RESULTS section 13;
        with PPO's ``update_epochs=8``, 16,000 brings get_gold to 0.89-0.91 in ~20,000
        episodes in all: section 15). The phase keeps
        climbing past 20,000: get_gem 0.77 -> 0.82 at 60,000 -> 0.84 at 100,000, with the
        compact observation 0.82 -> 0.85 at 60,000; get_gold passes 0.92 after ~28,000
        (section 18).
      finetune_plateau_episodes: the phase also ends once its task success stops climbing:
        whole-task episodes are taken in blocks of this many, and the phase ends when a
        block's mean teleport-free task success is less than ``finetune_plateau_gain`` above
        the block's before it (0: never; then only the gate or the budget end it). Blocks
        of 4,000 average out the episode-to-episode noise (+-0.008 on a success near 0.85)
        while a climb of 0.01 per 4,000 episodes still goes on; a task whose gate lies above
        what its maps allow (get_gem: the oracle's 0.895 below the gate's 0.92) stops where
        it flattens instead of spending the whole budget (benchmarks/RESULTS.md section 19).
      finetune_plateau_gain: the least rise of the block mean that counts as still climbing.
      finetune_agent: learner hyper-parameters that fine-tuning turns use instead of
        ``agent``'s (e.g. ``{"learning_rate": 1e-3}``); only those the learner keeps as
        traced leaves (PPO: learning_rate, gae_lambda, clip_eps, ent_coef, vf_coef, target_kl; DQN:
        learning_rate, epsilon_end, epsilon_decay_steps, target_update_period, tau,
        reward_scale; actor-critic: learning_rate, vf_coef, ent_coef), so the phase
        reuses the levels' compiled chunk. In a sweep they override the swept values too.
      finetune_side_cost: while fine-tuning, a template learner is also rewarded by the
        decrease of its template's ``side_cost`` where the environment defines one (Craft:
        items held beyond the one promised), so its run stops leaving behind what the task's
        reward penalises; F_o success and the levels are unchanged.
      finetune_side_cost_weight: the side costs' weight (1: as the templates declare them).
      level_side_cost_weight: the same shaping in the levels, at this weight (0: off): a
        template learner is charged for what it picks up beyond its promise while it first
        learns, where teleports below it never do (F_o success and thresholds unchanged).
      checkpoint_every: seconds between checkpoints when an output directory is given
        (0: after every chunk); a checkpoint is also written at the end of every level.
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
    finetune_plateau_gain: float = 0.01
    finetune_agent: dict = field(default_factory=dict)
    finetune_side_cost: bool = True
    finetune_side_cost_weight: float = 1.0
    level_side_cost_weight: float = 0.0
    checkpoint_every: float = 60.0
    tensorboard: bool = False
    agent: dict = field(default_factory=dict)
    levels: dict = field(default_factory=dict)

    def __post_init__(self):
        self.validate()

    def validate(self) -> None:
        def need(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ConfigError(f"config field {name!r} = {getattr(self, name)!r}: must be {allowed}")

        need(self.method in METHODS, "method", f"one of {METHODS}")
        need(self.algo in ALGOS, "algo", f"one of {ALGOS}")
        need(self.hierarchy is None or isinstance(self.hierarchy, str), "hierarchy", "a name or None")
        for name in ("num_envs", "rollout_ticks", "updates_per_chunk", "success_window",
                     "max_episodes_per_level", "eval_envs", "eval_max_ticks", "gate_envs",
                     "gate_max_ticks", "gate_interval", "finetune_turn_episodes",
                     "finetune_max_episodes"):
            value = getattr(self, name)
            need(isinstance(value, int) and not isinstance(value, bool) and value >= 1, name,
                 "an integer >= 1")
        for name in ("finetune_max_rest", "finetune_plateau_episodes"):
            value = getattr(self, name)
            need(isinstance(value, int) and not isinstance(value, bool) and value >= 0, name,
                 "an integer >= 0")
        need(isinstance(self.finetune_plateau_gain, (int, float))
             and not isinstance(self.finetune_plateau_gain, bool)
             and 0 <= self.finetune_plateau_gain <= 1, "finetune_plateau_gain", "in [0, 1]")
        need(self.reset_pool is None or (isinstance(self.reset_pool, int)
                                         and not isinstance(self.reset_pool, bool)
                                         and self.reset_pool >= 0),
             "reset_pool", "an integer >= 0, or null for num_envs")
        need(self.policy_memory in POLICY_MEMORIES, "policy_memory", f"one of {POLICY_MEMORIES}")
        need(self.frozen_eval in ("auto", "learned", "all"), "frozen_eval",
             "one of ('auto', 'learned', 'all')")
        need(isinstance(self.threshold, (int, float)) and 0 < self.threshold <= 1, "threshold",
             "in (0, 1]")
        need(isinstance(self.ceiling_fraction, (int, float))
             and not isinstance(self.ceiling_fraction, bool)
             and 0 < self.ceiling_fraction <= 1, "ceiling_fraction", "in (0, 1]")
        need(self.finetune in FINETUNE_CHOICES, "finetune", f"one of {FINETUNE_CHOICES}")
        need(self.finetune_mode in FINETUNE_MODES, "finetune_mode", f"one of {FINETUNE_MODES}")
        for name in ("finetune_threshold", "finetune_option_threshold"):
            value = getattr(self, name)
            need(isinstance(value, (int, float)) and not isinstance(value, bool)
                 and 0 < value <= 1, name, "in (0, 1]")
        need(isinstance(self.gamma, (int, float)) and 0 < self.gamma <= 1, "gamma", "in (0, 1]")
        need(self.frozen_policy in FROZEN_POLICIES, "frozen_policy", f"one of {FROZEN_POLICIES}")
        need(isinstance(self.option_temperature, (int, float))
             and not isinstance(self.option_temperature, bool)
             and 0 < self.option_temperature <= 10, "option_temperature", "in (0, 10]")
        need(isinstance(self.checkpoint_every, (int, float)) and self.checkpoint_every >= 0,
             "checkpoint_every", ">= 0 seconds")
        need(isinstance(self.tensorboard, bool), "tensorboard", "true or false")
        need(isinstance(self.continue_episodes, bool), "continue_episodes", "true or false")
        need(isinstance(self.gate, bool), "gate", "true or false")
        need(isinstance(self.finetune_side_cost, bool), "finetune_side_cost", "true or false")
        need(isinstance(self.finetune_continue_episodes, bool), "finetune_continue_episodes",
             "true or false")
        for name in ("finetune_side_cost_weight", "level_side_cost_weight"):
            value = getattr(self, name)
            need(isinstance(value, (int, float)) and not isinstance(value, bool)
                 and 0 <= value <= 100, name, "a number in [0, 100]")
        need(isinstance(self.agent, dict), "agent", "a mapping of learner hyper-parameters")
        need(isinstance(self.finetune_agent, dict) and all(
            isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
            and math.isfinite(v) for k, v in self.finetune_agent.items()),
             "finetune_agent", "a mapping of learner hyper-parameter names to numbers")
        if "gamma" in self.agent:  # one source: the trainer discounts with TrainConfig.gamma
            raise ConfigError(f"agent field 'gamma' = {self.agent['gamma']!r} would be ignored: the "
                              f"discount is the config field 'gamma'; set it with --set gamma=X "
                              f"(TrainConfig(gamma=X))")
        need(isinstance(self.max_steps_per_level, int) and not isinstance(self.max_steps_per_level, bool)
             and self.max_steps_per_level >= 0, "max_steps_per_level", "an integer >= 0 (0: no step budget)")
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
            raise ConfigError(f"unknown config field(s) {unknown}; valid fields: {sorted(names)}")
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
    """The one place a run's configuration is assembled (``smjax train``, ``run`` and
    ``load_trained`` / ``smjax render --policy`` all call it). Later sources override
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
        data = yaml.safe_load(text) if path.suffix in (".yaml", ".yml") else json.loads(text)
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
