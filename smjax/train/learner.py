"""The learner a run trains and the rules between it and the config, decided before the
engine builds anything from them."""
from __future__ import annotations

from smjax.train.config import ConfigError, TrainConfig


def make_learner(env, env_params, cfg: TrainConfig):
    """The learner ``cfg`` names (``cfg.algo`` with ``cfg.agent``), given the grids the
    environment declares in its observation (``Environment.observation_layout``), which a
    ``torso="conv"`` learner reads."""
    from smjax.agents import make_agent  # looked up at each call: tests replace it

    return make_agent(cfg.algo, layout=env.observation_layout(env_params), **cfg.agent)


def frozen_mode(cfg: TrainConfig, agent) -> str:
    """How frozen policies act: the config's choice, else what the learner declares."""
    return agent.frozen_policy if cfg.frozen_policy == "auto" else cfg.frozen_policy


def check_joint_learner(cfg: TrainConfig, agent) -> None:
    """Refuse joint fine-tuning of a recurrent policy (its memory is not carried across
    the options that joint fine-tuning trains at once)."""
    if cfg.fine_tuning.on and cfg.fine_tuning.mode == "joint" and agent.hidden_size:
        raise ConfigError("config field 'finetune_mode' = 'joint' does not run a recurrent "
                          "policy (--agent recurrent_size): add --finetune-mode turns "
                          "(finetune_mode: turns)")
