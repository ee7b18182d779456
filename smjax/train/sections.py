"""The training config in typed sections: what each part of training reads.

``TrainConfig`` keeps one flat set of fields (the YAML keys and ``--set`` names every run
records); the parts of training read typed sections of it, resolved once when the config
is made: ``cfg.run`` (:class:`Run`), ``cfg.fine_tuning`` (:class:`FineTuning`),
``cfg.evaluation`` (:class:`Evaluation`) and, per level, ``cfg.for_level(name)``
(``LevelSettings``).

A config file or ``--set`` may also name a field by its section, ``fine_tuning.threshold``
or a mapping ``fine_tuning: {threshold: 0.9}``; :data:`SECTIONS` is the one table that maps
each section field to its flat field (docs/guide.md, "TrainConfig reference").
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

# section -> {section field: TrainConfig field}
SECTIONS: dict[str, dict[str, str]] = {
    "run": {name: name for name in (
        "num_envs", "rollout_ticks", "updates_per_chunk", "reset_pool", "frozen_eval",
        "policy_memory", "checkpoint_every", "tensorboard")},
    "fine_tuning": {
        "enabled": "finetune", "mode": "finetune_mode", "threshold": "finetune_threshold",
        "option_threshold": "finetune_option_threshold",
        "turn_episodes": "finetune_turn_episodes", "max_rest": "finetune_max_rest",
        "continue_episodes": "finetune_continue_episodes",
        "max_episodes": "finetune_max_episodes",
        "plateau_episodes": "finetune_plateau_episodes",
        "plateau_gain": "finetune_plateau_gain", "agent": "finetune_agent",
        "side_cost": "finetune_side_cost", "side_cost_weight": "finetune_side_cost_weight",
    },
    "evaluation": {
        "gate": "gate", "gate_envs": "gate_envs", "gate_max_ticks": "gate_max_ticks",
        "gate_interval": "gate_interval", "eval_envs": "eval_envs",
        "eval_max_ticks": "eval_max_ticks", "eval_policies": "eval_policies",
    },
}


class SectionError(ValueError):
    """A section or section field that does not exist."""


@dataclass(frozen=True)
class Run:
    """How every seed's ticks run (the rollout's shape, the runner's structure) and what
    the run writes beside its results."""

    num_envs: int             # parallel environments per seed
    rollout_ticks: int        # ticks per rollout (one learner update per rollout)
    updates_per_chunk: int    # rollouts per compiled chunk
    reset_pool: int | None    # as given (None: ``num_envs``); ``pool_size`` resolves it
    frozen_eval: str          # how a tick runs the policy bank ("auto": by backend)
    policy_memory: str        # "none" or "last_action"
    checkpoint_every: float   # seconds between checkpoints (0: every chunk)
    tensorboard: bool         # also write TensorBoard event files

    @property
    def pool_size(self) -> int:
        """Episode starts per rollout (0: none, reset every tick)."""
        return self.num_envs if self.reset_pool is None else self.reset_pool

    @property
    def steps_per_update(self) -> int:
        """Env steps of one seed's rollout (one learner update)."""
        return self.num_envs * self.rollout_ticks

    @property
    def steps_per_chunk(self) -> int:
        """Env steps of one seed's chunk."""
        return self.steps_per_update * self.updates_per_chunk

    @classmethod
    def of(cls, cfg) -> "Run":
        return cls(**section_values(cfg, "run"))


@dataclass(frozen=True)
class FineTuning:
    """The teleport-free fine-tuning phase after the levels (``smjax.train.finetune``)."""

    on: bool                  # ``finetune`` resolved ("auto": on for top-down)
    mode: str                 # "joint" or "turns"
    threshold: float          # the teleport-free task success whose gate ends the phase
    option_threshold: float   # turns: an option's running success that ends its turn
    turn_episodes: int        # turns: episodes of one turn at most
    max_rest: int             # turns: turns in a row a converged option may sit out
    continue_episodes: bool   # turns: episodes in flight go on into the next turn
    max_episodes: int         # the phase's episode budget per seed
    plateau_episodes: int     # block size of the plateau rule (0: no plateau rule)
    plateau_gain: float       # the least rise of a block's mean that counts as climbing
    agent: dict               # learner hyper-parameter leaves used instead of ``agent``'s
    side_cost: float          # weight of the templates' side cost (0: none)

    @classmethod
    def of(cls, cfg) -> "FineTuning":
        return cls(
            on=cfg.finetune == "on" or (cfg.finetune == "auto" and cfg.method == "top-down"),
            mode=cfg.finetune_mode, threshold=cfg.finetune_threshold,
            option_threshold=cfg.finetune_option_threshold,
            turn_episodes=cfg.finetune_turn_episodes, max_rest=cfg.finetune_max_rest,
            continue_episodes=cfg.finetune_continue_episodes,
            max_episodes=cfg.finetune_max_episodes,
            plateau_episodes=cfg.finetune_plateau_episodes,
            plateau_gain=cfg.finetune_plateau_gain, agent=dict(cfg.finetune_agent),
            side_cost=cfg.finetune_side_cost_weight if cfg.finetune_side_cost else 0.0)


@dataclass(frozen=True)
class Evaluation:
    """The gate (fresh episodes of the policy to be frozen) and the final evaluation."""

    gate: bool
    gate_envs: int
    gate_max_ticks: int
    gate_interval: int
    eval_envs: int
    eval_max_ticks: int
    eval_policies: str        # "run": the run's frozen policy alone; "all": every mode

    @classmethod
    def of(cls, cfg) -> "Evaluation":
        return cls(**section_values(cfg, "evaluation"))


def section_values(cfg, section: str) -> dict:
    """A section's fields, read from the config's flat fields by the table."""
    return {name: getattr(cfg, flat) for name, flat in SECTIONS[section].items()}


def flatten_sections(data: dict) -> dict:
    """``data`` with every section entry (``"fine_tuning": {...}`` or
    ``"fine_tuning.threshold": x``) as its flat field; a flat field given twice (by its
    name and its section) is refused."""
    out: dict[Any, Any] = {}

    def put(flat: str, value: Any, given_as: str) -> None:
        if flat in out:
            raise SectionError(f"config field {flat!r} is given twice (also as {given_as!r}); "
                               f"give it once")
        out[flat] = value

    for key, value in data.items():
        section, dot, name = key.partition(".") if isinstance(key, str) else (key, "", "")
        if section in SECTIONS and not dot:
            if not isinstance(value, dict):
                raise SectionError(f"config section {section!r} must be a mapping of its "
                                   f"fields {sorted(SECTIONS[section])}, got {value!r}")
            for field, item in value.items():
                put(section_field(section, field), item, f"{section}.{field}")
        elif section in SECTIONS:
            put(section_field(section, name), value, key)
        else:
            put(key, value, key)
    return out


def section_field(section: str, name: Any) -> str:
    """The flat field of ``section.name``."""
    fields = SECTIONS[section]
    if name not in fields:
        raise SectionError(f"config section {section!r} has no field {name!r}; its fields: "
                           f"{sorted(fields)}")
    return fields[name]
