"""Fine-tuning's pure helpers: its learner hyper-parameters, the order of its turns, and
the bank operations of turns (an option's row per seed) and of joint fine-tuning (a
learner per option)."""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.train.config import ConfigError, TrainConfig
from smjax.train.learner import update_fields


def next_turn(turn: int, order: list[str], turns: list[dict], rested: dict[str, int],
              threshold: float, max_rest: int) -> int:
    """The turn index after ``turn`` (its option: ``order[index % len(order)]``), skipping
    resting options; updates ``rested`` (template -> turns sat out in a row).

    An option rests while its last turn (in ``turns``, the phase's record) ended with
    running success >= ``threshold``, for at most ``max_rest`` turns in a row: then it
    plays again, so an option whose callers have moved on is checked where they now call
    it. Ends: each skip raises a counter that stops at ``max_rest``."""
    last = {t["template"]: t["running_success"] for t in turns}
    index = turn + 1
    while True:
        name = order[index % len(order)]
        success = last.get(name)
        if success is None or success < threshold or rested.get(name, 0) >= max_rest:
            rested[name] = 0
            return index
        rested[name] = rested.get(name, 0) + 1
        index += 1


@jax.jit
def bank_rows(bank, options: jax.Array):
    """Per seed (leading axis), the bank's params of option ``options[s]``."""
    rows = jnp.arange(options.shape[0])
    return jax.tree.map(lambda b: b[rows, options], bank)


@jax.jit
def store_learned(mask: jax.Array, learned: jax.Array, params, bank):
    """Per masked seed, ``params`` [S, O, ...] (a learner per option) stored in the bank at
    every learned option; the rest of the bank is kept."""
    keep = mask[:, None] & learned

    def pick(p, b):
        return jnp.where(keep.reshape(keep.shape + (1,) * (p.ndim - 2)), p, b)

    return jax.tree.map(pick, params, bank)


def finetune_hp(cfg: TrainConfig, hp: dict) -> dict:
    """``cfg.fine_tuning.agent`` as the learner's per-slot hyper-parameter leaves (``hp``: a
    fresh learner's)."""
    check_finetune_agent(cfg, hp)
    return {k: jnp.full_like(hp[k], v) for k, v in cfg.fine_tuning.agent.items() if k in hp}


def check_finetune_agent(cfg: TrainConfig, hp) -> None:
    """``cfg.fine_tuning.agent`` names only hyper-parameters the learner reads per turn
    (``hp``: a fresh learner's, or their names) and its update's settings
    (``learner.update_fields``)."""
    unknown = sorted(set(cfg.fine_tuning.agent) - set(hp) - set(update_fields(cfg)))
    if unknown:
        raise ConfigError(f"config field 'finetune_agent' names {unknown}, which the "
                          f"{cfg.algo} learner does not read per turn; it reads {sorted(hp)} "
                          "(and joint fine-tuning's update takes its settings, such as "
                          "update_epochs)")
