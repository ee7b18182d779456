"""The learner a run trains and the rules between it and the config, decided before the
engine builds anything from them."""
from __future__ import annotations

import dataclasses

import jax

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


def update_fields(cfg: TrainConfig) -> dict:
    """The fields of ``cfg.finetune_agent`` that are not traced hyper-parameters: settings
    of the learner's update (its epochs, its minibatches) that joint fine-tuning's update
    is built with instead of ``cfg.agent``'s."""
    return _static_settings(cfg.algo, cfg.fine_tuning.agent)


def agent_fields_in_programs(cfg: TrainConfig) -> dict:
    """``cfg.agent`` and ``cfg.finetune_agent`` without their traced hyper-parameters: what
    the training and episodes programs depend on of them. Those read traced values from the
    learner's state; only the learners' init, which writes them there, depends on them."""
    return {"agent": _static_settings(cfg.algo, cfg.agent), "finetune_agent": update_fields(cfg)}


def _static_settings(algo: str, settings: dict) -> dict:
    """``settings``' fields that ``algo``'s learner is built from (not traced)."""
    from smjax.agents import default_config
    from smjax.agents.config import traced_fields

    config = default_config(algo)
    static = {f.name for f in dataclasses.fields(config)} - set(traced_fields(config))
    return {k: v for k, v in settings.items() if k in static}


def make_joint_learner(env, env_params, cfg: TrainConfig, agent):
    """The learner whose update joint fine-tuning runs: ``agent``, or where
    ``cfg.finetune_agent`` sets update settings (:func:`update_fields`), ``agent`` built
    with them, which the engine checks has the same state (:func:`check_same_state`)."""
    from smjax.agents import make_agent

    fields = update_fields(cfg)
    if not fields or not cfg.fine_tuning.on:
        return agent
    if cfg.fine_tuning.mode != "joint":
        raise ConfigError(f"config field 'finetune_agent' sets {sorted(fields)}, which only "
                          "joint fine-tuning's update reads: use --finetune-mode joint, or "
                          "set them for the whole run with --agent")
    return make_agent(cfg.algo, layout=env.observation_layout(env_params),
                      **(cfg.agent | fields))


def check_same_state(agent, joint_agent, example_obs, num_actions: int) -> None:
    """Joint fine-tuning's learner must take the levels' learners as they are: the same
    state, leaf for leaf (only its update may differ)."""
    def state_of(learner):
        state = jax.eval_shape(lambda k: learner.init(k, example_obs, num_actions),
                               jax.random.PRNGKey(0))
        leaves, tree = jax.tree.flatten(state)
        return tree, [(x.shape, x.dtype) for x in leaves]

    if state_of(joint_agent) != state_of(agent):
        raise ConfigError("config field 'finetune_agent' changes the learner's state (its "
                          "parameters or optimiser): in fine-tuning it may set only "
                          "hyper-parameters and the update's settings (epochs, minibatches)")
