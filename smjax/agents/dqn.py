"""DQN over SMDP decisions, with the replay buffer held as arrays in the agent state.

Each ``update`` call turns the rollout into SMDP transitions (one per learner decision,
see :func:`smjax.agents.smdp.smdp_transitions`), writes them into a fixed-capacity
circular buffer, then takes ``gradient_steps_per_update`` gradient steps on uniformly
sampled minibatches. The target of a transition is

    R + D * (1 - terminal) * max_{a' allowed at s'} Q_target(s', a')

with R the discounted reward sum of the ticks until the next decision and D the product
of their discounts (gamma**k, or gamma**d for teleported template calls); the stored
action mask of the next decision restricts the max (double DQN: argmax by the online
network, value by the target network). A decision still pending at the rollout end is not
stored: the caller carries it into the next rollout (``smdp.carry_pending``), where it is
stored once complete, with its true next decision state and mask.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import flax.struct
import jax
import jax.numpy as jnp
import optax

from smjax.agents import config as checks
from smjax.agents.base import ActOutput, Agent, Transition, hyper_params, scale_by_lr
from smjax.agents.config import static, traced
from smjax.agents.networks import (
    QNetwork,
    epsilon_greedy_log_probs,
    flatten_obs,
    greedy_masked,
    masked_logits,
    sample_from_log_probs,
    take_action,
    torso_grids,
    uniform_allowed_probs,
)
from smjax.agents.dqn_options import make_update_options
from smjax.agents.dqn_update import ReplayBuffer, dqn_update, empty_buffer, linear_epsilon


@dataclass(frozen=True)
class DQNConfig:
    """DQN's settings; ``traced`` ones are read from ``state.hp`` and may be swept,
    ``static`` ones build the program (:mod:`smjax.agents.config`)."""

    learning_rate: float = traced(2.5e-4)
    gamma: float = static(0.99)  # for the trainer's Transition.discount; not read here
    hidden_sizes: tuple[int, ...] = static((64, 64))
    activation: str = static("relu")
    # "conv": convolutions over the observation's declared grids, as PPOConfig's
    torso: str = static("mlp")
    conv_features: tuple[int, ...] = static((16, 16))
    buffer_capacity: int = static(10_000)
    batch_size: int = static(64)
    gradient_steps_per_update: int = static(1)
    learning_starts: int = static(1_000)  # transitions in the buffer before the first step
    target_update_period: int = traced(100)  # gradient steps between target updates
    tau: float = traced(1.0)  # 1 = hard copy; < 1 = Polyak averaging
    epsilon_start: float = static(1.0)
    epsilon_end: float = traced(0.05)
    epsilon_decay_steps: int = traced(10_000)
    epsilon_schedule_unit: str = static("decisions")  # or "gradient_steps"
    double_dqn: bool = static(True)
    huber_loss: bool = static(True)
    max_grad_norm: float = static(10.0)
    reward_scale: float = traced(1.0)  # rewards are multiplied by this before the TD target
    # how joint fine-tuning updates its learners, as PPOConfig's option_update: "grouped"
    # (``dqn_options``: the rollout stored by row index, the same buffers and steps),
    # "per_option" (each option's update over every row, vmapped) or "auto" (grouped: faster
    # on a CPU and a GPU, benchmarks/RESULTS.md, "The cost of a joint update")
    option_update: str = static("auto")

    def __post_init__(self):
        checks.check_range(self, "learning_rate", 0.0, 1.0, low_open=True)
        checks.check_range(self, "gamma", 0.0, 1.0)
        checks.check_range(self, "reward_scale", 0.0, 1e6, low_open=True)
        checks.check_hidden_sizes(self)
        checks.check_torso(self)
        checks.check_choice(self, "activation", ("tanh", "relu", "gelu", "elu", "swish"))
        for name in ("buffer_capacity", "batch_size", "gradient_steps_per_update",
                     "target_update_period", "epsilon_decay_steps"):
            checks.check_positive_int(self, name)
        checks.check_non_negative_int(self, "learning_starts")
        checks.check_range(self, "tau", 0.0, 1.0, low_open=True)
        checks.check_range(self, "epsilon_start", 0.0, 1.0)
        checks.check_range(self, "epsilon_end", 0.0, 1.0)
        checks.check_choice(self, "epsilon_schedule_unit", ("decisions", "gradient_steps"))
        checks.check_range(self, "max_grad_norm", 0.0, low_open=True)
        checks.check_choice(self, "option_update", ("auto", "grouped", "per_option"))


@flax.struct.dataclass
class DQNState:
    params: Any
    target_params: Any
    opt_state: Any
    buffer: ReplayBuffer
    grad_steps: jax.Array
    updates: jax.Array
    episodes_seen: jax.Array
    decisions_seen: jax.Array
    hp: Any = flax.struct.field(default_factory=dict)  # the config's traced fields (base.py)


def smdp_td_targets(q_next_online, q_next_target, reward, discount, terminal, next_mask, double_dqn):
    """``R + D * (1 - terminal) * Q_target(s', a*)`` with a* the best allowed next action."""
    if double_dqn:
        best = greedy_masked(q_next_online, next_mask)
    else:
        best = greedy_masked(q_next_target, next_mask)
    q_next = take_action(q_next_target, best)
    q_next = jnp.where(jnp.any(next_mask, axis=-1), q_next, 0.0)
    return reward + discount * (1.0 - terminal.astype(jnp.float32)) * q_next


def make_agent(config: DQNConfig | None = None, layout=()) -> Agent:
    """``layout``: the observation's grids, read by a "conv" torso (``ppo.make_agent``)."""
    config = DQNConfig() if config is None else config
    optimizer = optax.chain(
        optax.clip_by_global_norm(config.max_grad_norm), optax.scale_by_adam()  # lr: state.hp
    )

    def network_for(num_actions: int) -> QNetwork:
        return QNetwork(num_actions, tuple(config.hidden_sizes), config.activation,
                        torso_grids(config.torso, layout), tuple(config.conv_features))

    def q_values(params, obs: jax.Array) -> jax.Array:
        num_actions = params["params"]["q_head"]["kernel"].shape[-1]
        return network_for(num_actions).apply(params, flatten_obs(obs))

    def init(key: jax.Array, example_obs: jax.Array, num_actions: int) -> DQNState:
        num_actions = checks.check_num_actions(num_actions)
        example_obs = jnp.asarray(example_obs)
        params = network_for(num_actions).init(key, flatten_obs(example_obs[None]))
        buffer = empty_buffer(config.buffer_capacity, example_obs, num_actions)
        zero = jnp.zeros((), jnp.int32)
        return DQNState(params, params, optimizer.init(params), buffer, zero, zero, zero, zero,
                        hyper_params(config))

    def act(state: DQNState, obs: jax.Array, mask: jax.Array, key: jax.Array) -> ActOutput:
        q = q_values(state.params, obs)
        epsilon = linear_epsilon(config, state.hp, state.grad_steps, state.decisions_seen)
        key_explore, key_random = jax.random.split(key)
        random_action = sample_from_log_probs(key_random, jnp.log(uniform_allowed_probs(mask)), mask)
        explore = jax.random.uniform(key_explore, mask.shape[:-1]) < epsilon
        action = jnp.where(explore, random_action, greedy_masked(q, mask))
        log_prob = take_action(epsilon_greedy_log_probs(q, mask, epsilon), action)
        value = jnp.max(masked_logits(q, mask), axis=-1)
        return ActOutput(action, log_prob, value)

    step = functools.partial(gradient_step, config, optimizer,
                             functools.partial(td_loss, config, q_values))

    def update(state: DQNState, traj: Transition, key: jax.Array):
        return dqn_update(config, step, state, traj, key)

    def policy_logits(params, obs: jax.Array) -> jax.Array:
        return q_values(params, obs)

    def warm_start(state: DQNState, params) -> DQNState:
        # the target starts equal to the trained net; exploration at its final epsilon
        seen = jnp.ceil(state.hp["epsilon_decay_steps"]).astype(jnp.int32)
        return state.replace(params=params, target_params=params, decisions_seen=seen,
                             grad_steps=jnp.maximum(state.grad_steps, seen))

    grouped = config.option_update != "per_option"
    return Agent("dqn", init, act, update, policy_logits, "greedy", warm_start,
                 update_options=make_update_options(config, step) if grouped else None)


def td_loss(config: DQNConfig, q_values, params, target_params, batch):
    """(loss, (mean Q, mean |TD error|)) of a sampled minibatch ``batch``."""
    q = take_action(q_values(params, batch["obs"]), batch["action"])
    q_next_target = q_values(target_params, batch["next_obs"])
    q_next_online = q_values(params, batch["next_obs"]) if config.double_dqn else q_next_target
    target = jax.lax.stop_gradient(smdp_td_targets(
        q_next_online, q_next_target, batch["reward"], batch["discount"], batch["terminal"],
        batch["next_mask"], config.double_dqn))
    td = q - target
    per_item = optax.huber_loss(q, target) if config.huber_loss else 0.5 * jnp.square(td)
    return per_item.mean(), (q.mean(), jnp.abs(td).mean())


def gradient_step(config: DQNConfig, optimizer, loss_fn, state: DQNState, key: jax.Array):
    """One step on a minibatch drawn from the buffer (none before ``learning_starts``)."""
    buffer = state.buffer
    ready = buffer.size >= jnp.maximum(config.learning_starts, 1)
    idx = jax.random.randint(key, (config.batch_size,), 0, jnp.maximum(buffer.size, 1))
    batch = {name: getattr(buffer, name)[idx] for name in
             ("obs", "action", "reward", "discount", "terminal", "next_obs", "next_mask")}
    (loss, (mean_q, td_abs)), grads = jax.value_and_grad(loss_fn, has_aux=True)(
        state.params, state.target_params, batch)
    updates, opt_state = optimizer.update(grads, state.opt_state, state.params)
    updates = scale_by_lr(updates, state.hp["learning_rate"])
    params = optax.apply_updates(state.params, updates)
    grad_steps = state.grad_steps + 1
    period = jnp.round(state.hp["target_update_period"]).astype(jnp.int32)
    sync = grad_steps % period == 0
    tau = state.hp["tau"]
    target = jax.tree.map(
        lambda t, p: jnp.where(sync, tau * p + (1.0 - tau) * t, t),
        state.target_params, params)
    # Before learning_starts nothing changes (the buffer is still filling). Select only
    # the learned parts: a select over the buffer would copy it on every step.
    params, target, opt_state, grad_steps = jax.tree.map(
        lambda n, o: jnp.where(ready, n, o),
        (params, target, opt_state, grad_steps),
        (state.params, state.target_params, state.opt_state, state.grad_steps))
    new_state = state.replace(params=params, target_params=target, opt_state=opt_state,
                              grad_steps=grad_steps)
    metrics = {"loss": loss, "mean_q": mean_q, "td_error_abs": td_abs,
               "stepped": ready.astype(jnp.float32)}
    return new_state, metrics
