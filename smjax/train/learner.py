"""The learner a run trains and the rules between it and the config, decided before the
engine builds anything from them."""
from __future__ import annotations

from smjax.train.config import ConfigError, TrainConfig


def make_learner(env, env_params, cfg: TrainConfig):
    """The learner ``cfg`` names (``cfg.algo`` with ``cfg.agent``), given the grids the
    environment declares in its observation (``Environment.observation_layout``), which a
    ``torso="conv"`` learner reads; refused where the config asks what it cannot do."""
    from smjax.agents import make_agent  # looked up at each call: tests replace it

    agent = make_agent(cfg.algo, layout=env.observation_layout(env_params), **cfg.agent)
    # joint fine-tuning trains every option at once, and a recurrent policy's memory is
    # not carried across options
    if cfg.fine_tuning.on and cfg.fine_tuning.mode == "joint" and agent.hidden_size:
        raise ConfigError("config field 'finetune_mode' = 'joint' does not run a recurrent "
                          "policy (--agent recurrent_size): add --finetune-mode turns "
                          "(finetune_mode: turns)")
    return agent
