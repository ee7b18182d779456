"""PPO for discrete, masked actions over SMDP decisions.

The rollout ``Transition[T, B]`` holds every tick; only ticks with a complete decision
train (a decision pending at the rollout end returns as row 0 of the next rollout, see
:mod:`smjax.agents.smdp`): every loss term is a mean over those ticks (the others weigh
0), advantages come from :func:`smjax.agents.smdp.smdp_gae` and are normalised over those
decisions only. Minibatches partition the T*B ticks with the decisions dealt evenly among
them (every minibatch gets the same number of decisions, +-1, however rarely the learner
decides); the masked mean keeps each minibatch's loss a proper average, and a minibatch without
any decision leaves the parameters and optimiser untouched. The compute is that of all
T*B ticks (static shapes), so very sparse decisions cost as much as dense ones.

``gamma`` is not read by the update: the per-tick discounts arrive in
``Transition.discount``. It is part of the config so that the trainer building those
discounts has a single place to read it from.
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
    ActorCritic,
    RecurrentActorCritic,
    epsilon_mixture_log_probs,
    flatten_obs,
    masked_log_softmax,
    sample_from_log_probs,
    take_action,
    torso_grids,
)
from smjax.agents.ppo_options import make_option_values, make_update_options
from smjax.agents.ppo_update import (apply_if, decision_data, decision_order, finish, kl_stop,
                                     loss_terms, num_actions_of)


@dataclass(frozen=True)
class PPOConfig:
    """PPO's settings; ``traced`` ones are read from ``state.hp`` and may be swept,
    ``static`` ones build the program (:mod:`smjax.agents.config`)."""

    # 5e-4, not PureJaxRL's 2.5e-4: Craft's levels need a quarter fewer episodes with it
    learning_rate: float = traced(5e-4)
    gamma: float = static(0.99)
    gae_lambda: float = traced(0.95)
    clip_eps: float = traced(0.2)
    ent_coef: float = traced(0.01)
    vf_coef: float = traced(0.5)
    max_grad_norm: float = static(0.5)
    # 4: at 8 the hierarchy's levels are a little cheaper, but flat PPO collapses on long
    # sparse tasks, and the flat baseline must not be broken by the defaults
    update_epochs: int = static(4)
    num_minibatches: int = static(4)
    # Early stop on the policy's drift (0: never): once a minibatch's approximate
    # KL(old || new) exceeds 1.5 x target_kl, the rest of the update's minibatches and
    # epochs leave the parameters alone (the Stable-Baselines3 rule). It bounds how far
    # many epochs can push the policy from the one that gathered the data.
    target_kl: float = traced(0.0)
    hidden_sizes: tuple[int, ...] = static((64, 64))
    activation: str = static("tanh")
    shared_torso: bool = static(False)
    # "conv": the observation's declared grids (Craft's windows) pass through 3 x 3
    # convolutions of ``conv_features`` channels per layer before the dense layers
    # (networks.GridEncoder; the environment declares them: Environment.observation_layout)
    torso: str = static("mlp")
    conv_features: tuple[int, ...] = static((16, 16))
    # A recurrent policy (0: memoryless): a GRU memory of this width, carried from each of
    # the option's decisions to its next (``networks.RecurrentActorCritic``), trained by
    # backpropagation through the rollout, minibatches then being sets of environments.
    # For observations that cannot tell places apart: a memoryless policy that picks
    # greedily loops where it cannot see what changed.
    recurrent_size: int = static(0)
    normalize_advantages: bool = static(True)
    clip_value_loss: bool = static(True)
    adam_eps: float = static(1e-5)
    # Joint fine-tuning's update (a learner per option) runs each option's decisions
    # through its network in blocks of this many rows (``ppo_options``): the speed
    # changes, the result does not (up to the order of float sums)
    option_block: int = static(128)
    # blocks per pass of that loop (0: one on a CPU, on an accelerator as many as a
    # minibatch usually fills: ``smjax.agents.grouped.blocks_per_step``): the speed
    # changes, the result does not
    option_blocks_per_step: int = static(0)
    # how joint fine-tuning updates its learners: "grouped" (every option's own decisions
    # in one pass: the work follows the decisions), "per_option" (each option's update over
    # the whole batch, masked, vmapped over options: one wide kernel per layer), or "auto"
    # (grouped: the faster on a CPU and, its blocks batched, on a GPU)
    option_update: str = static("auto")

    def __post_init__(self):
        checks.check_range(self, "learning_rate", 0.0, 1.0, low_open=True)
        checks.check_range(self, "gamma", 0.0, 1.0)
        checks.check_range(self, "gae_lambda", 0.0, 1.0)
        checks.check_range(self, "clip_eps", 0.0, 1.0, low_open=True)
        checks.check_range(self, "ent_coef", 0.0)
        checks.check_range(self, "vf_coef", 0.0)
        checks.check_range(self, "max_grad_norm", 0.0, low_open=True)
        checks.check_positive_int(self, "update_epochs")
        checks.check_positive_int(self, "num_minibatches")
        checks.check_range(self, "target_kl", 0.0)
        checks.check_positive_int(self, "option_block")
        checks.check_non_negative_int(self, "option_blocks_per_step")
        checks.check_choice(self, "option_update", ("auto", "grouped", "per_option"))
        checks.check_hidden_sizes(self)
        checks.check_non_negative_int(self, "recurrent_size")
        checks.check_torso(self)
        if self.recurrent_size and self.torso == "conv":
            raise ValueError("recurrent_size > 0 runs the dense torso only: use torso='mlp'")
        if self.recurrent_size and self.shared_torso:
            raise ValueError("recurrent_size > 0 needs shared_torso=False (the recurrent "
                             "network gives actor and critic their own torso)")
        checks.check_choice(self, "activation", ("tanh", "relu", "gelu", "elu", "swish"))
        checks.check_range(self, "adam_eps", 0.0, low_open=True)


@flax.struct.dataclass
class PolicyGradientState:
    """Learner state of PPO and the actor-critic (counters are int32 scalars)."""

    params: Any
    opt_state: Any
    grad_steps: jax.Array
    updates: jax.Array
    episodes_seen: jax.Array
    decisions_seen: jax.Array
    hp: Any = flax.struct.field(default_factory=dict)  # the config's traced fields (base.py)


def make_network(num_actions: int, hidden_sizes, activation: str, shared_torso: bool,
                 grids=(), conv_features=(16, 16)):
    return ActorCritic(num_actions, tuple(hidden_sizes), activation, shared_torso, tuple(grids),
                       tuple(conv_features))


def init_policy_gradient_state(network_for, optimizer, key, example_obs, num_actions, hp,
                               memory_size: int = 0):
    """Shared ``init`` of the actor-critic-network learners (``memory_size``: a recurrent
    network's memory width, 0 for a memoryless one)."""
    network = network_for(checks.check_num_actions(num_actions))
    inputs = (flatten_obs(jnp.asarray(example_obs)[None]),)
    if memory_size:
        inputs += (jnp.zeros((1, memory_size), jnp.float32),)
    params = network.init(key, *inputs)
    zero = jnp.zeros((), jnp.int32)
    return PolicyGradientState(params, optimizer.init(params), zero, zero, zero, zero, hp)


def sample_actions(network_for, params, obs, mask, key, epsilon=None) -> ActOutput:
    """Sample from ``(1 - epsilon) * pi + epsilon * uniform(allowed)``; never a masked action.

    ``epsilon=None`` samples from pi itself (exact log-probabilities, as PPO's ratio needs).
    """
    network = network_for(num_actions_of(params))
    logits, value = network.apply(params, flatten_obs(obs))
    return sample_from_logits(logits, value, mask, key, epsilon)


def sample_from_logits(logits, value, mask, key, epsilon=None) -> ActOutput:
    """``sample_actions`` from a network's outputs already computed."""
    log_probs = masked_log_softmax(logits, mask)
    if epsilon is not None:
        log_probs = epsilon_mixture_log_probs(log_probs, mask, epsilon)
    action = sample_from_log_probs(key, log_probs, mask)
    return ActOutput(action, take_action(log_probs, action), value)


def logits_of(network_for, params, obs) -> jax.Array:
    logits, _ = network_for(num_actions_of(params)).apply(params, flatten_obs(obs))
    return logits


def minibatch_indices(key: jax.Array, decision: jax.Array, num_minibatches: int):
    """Shuffled indices ``[M, S]`` over all items, decisions dealt evenly to minibatches.

    Decisions are put first in random order, then item p goes to minibatch p % M, so
    every minibatch holds the same number of decisions (+-1) however sparse they are.
    Returns the indices and a flag that is False on padding entries.
    """
    num_items = decision.shape[0]
    size = -(-num_items // num_minibatches)
    pad = num_minibatches * size - num_items
    order = decision_order(key, decision)
    idx = jnp.concatenate([order, jnp.zeros((pad,), order.dtype)])
    real = jnp.concatenate([jnp.ones((num_items,), bool), jnp.zeros((pad,), bool)])
    return idx.reshape(size, num_minibatches).T, real.reshape(size, num_minibatches).T


def unroll(network: RecurrentActorCritic, params, inputs) -> tuple[jax.Array, jax.Array]:
    """Logits and values ``[T, B, ...]`` of a recurrent policy replayed over a rollout.

    ``inputs = (obs [T, B, F], memory [T, B, H], decided [T, B], done [T, B])``: the flat
    observations, the memory that entered each tick (``Transition.hidden``), the ticks
    where the policy chose, and its episode ends. Within one run of the option the memory
    is recomputed from the run's earlier decisions, so gradients flow back through them;
    a run's first decision in the rollout starts from the memory the runner recorded
    (zero where the run begins there; a run that began in an earlier rollout is where the
    backpropagation is truncated). With the parameters that acted, the replay gives the
    rollout's own logits (tests/test_recurrent.py)."""
    obs, stored, decided, done = inputs
    # the torsos do not read the memory: all ticks at once, only the cell step by step
    features = network.apply(params, obs, method=network.encode)

    def step(carry, row):
        h, linked = carry
        feats, h_stored, dec, end = row
        h_in = jnp.where(linked[:, None], h, h_stored)
        logits, value, h_out = network.apply(params, feats, h_in, method=network.decide)
        h = jnp.where(dec[:, None], h_out, h)
        return (h, (linked | dec) & ~end), (logits, value)

    init = (jnp.zeros_like(stored[0]), jnp.zeros(decided.shape[1:], bool))
    _, (logits, value) = jax.lax.scan(step, init, (features, stored, decided, done))
    return logits, value


def make_agent(config: PPOConfig | None = None, layout=()) -> Agent:
    """``layout``: the observation's grids (``Environment.observation_layout``), read by a
    "conv" torso."""
    config = PPOConfig() if config is None else config
    # optax.adam without its learning rate, which is applied from state.hp (scale_by_lr)
    optimizer = optax.chain(
        optax.clip_by_global_norm(config.max_grad_norm),
        optax.scale_by_adam(eps=config.adam_eps),
    )
    memory = config.recurrent_size

    def network_for(num_actions: int):
        if memory:
            return RecurrentActorCritic(num_actions, tuple(config.hidden_sizes),
                                        config.activation, memory)
        return make_network(num_actions, config.hidden_sizes, config.activation, config.shared_torso,
                            torso_grids(config.torso, layout), config.conv_features)

    def init(key: jax.Array, example_obs: jax.Array, num_actions: int) -> PolicyGradientState:
        return init_policy_gradient_state(network_for, optimizer, key, example_obs, num_actions,
                                          hyper_params(config), memory)

    def act(state: PolicyGradientState, obs: jax.Array, mask: jax.Array, key: jax.Array) -> ActOutput:
        return sample_actions(network_for, state.params, obs, mask, key)

    def policy_logits(params, obs: jax.Array) -> jax.Array:
        return logits_of(network_for, params, obs)

    def act_recurrent(state: PolicyGradientState, obs: jax.Array, mask: jax.Array,
                      key: jax.Array, hidden: jax.Array) -> tuple[ActOutput, jax.Array]:
        network = network_for(num_actions_of(state.params))
        logits, value, hidden = network.apply(state.params, flatten_obs(obs), hidden)
        return sample_from_logits(logits, value, mask, key), hidden

    def policy_logits_recurrent(params, obs: jax.Array, hidden: jax.Array):
        logits, _, hidden = network_for(num_actions_of(params)).apply(
            params, flatten_obs(obs), hidden)
        return logits, hidden

    def update(state: PolicyGradientState, traj: Transition, key: jax.Array):
        return ppo_update(config, network_for, optimizer, state, traj, key)

    if memory:
        return Agent("ppo", init, act_recurrent, update, policy_logits_recurrent,
                     hidden_size=memory)
    grouped = config.option_update != "per_option"
    return Agent("ppo", init, act, update, policy_logits,
                 update_options=make_update_options(config, network_for, optimizer,
                                                    config.option_block) if grouped else None,
                 option_values=make_option_values(config, network_for) if grouped else None)


def ppo_loss(config: PPOConfig, network_for, params, batch, hp):
    """PPO's loss on one minibatch ``batch`` (``ppo_update``'s data, taken at its rows)."""
    mask = batch[2]
    if config.recurrent_size:  # [T, B_mb, ...] sequences: whole rollouts of some environments
        logits, value = unroll(network_for(mask.shape[-1]), params, batch[0])
    else:       # [N] ticks
        logits, value = network_for(mask.shape[-1]).apply(params, batch[0])
    return loss_terms(config, logits, value, batch[1:], hp)


def minibatch_source(traj: Transition, fields: tuple, memory: int):
    """(data, take, weight_of): the update's arrays, how a minibatch takes its rows
    ``take(x, idx)``, and its decision weights ``weight_of(w, real)`` without padding."""
    num_ticks, num_envs = traj.reward.shape[:2]
    num_items = num_ticks * num_envs
    # in the rollout's own dtype: a minibatch casts its rows to float32 once taken
    # (``as_float``), so its gather reads a uint8 observation's bytes, not 4x as many
    obs = traj.obs.reshape((num_ticks, num_envs, -1))
    if memory:  # the unroll also needs the memory, decided and done of every tick
        obs = (obs, traj.hidden.astype(jnp.float32), traj.decision.astype(bool),
               traj.done.astype(bool))
    data = (obs,) + fields
    if memory:  # minibatches are sets of environments, each with its whole rollout
        take = lambda x, idx: x[:, idx]  # noqa: E731
        weight_of = lambda w, real: w & real[None, :]  # noqa: E731
    else:       # minibatches are sets of ticks
        data = jax.tree.map(lambda x: x.reshape((num_items,) + x.shape[2:]), data)
        take = lambda x, idx: x[idx]  # noqa: E731
        weight_of = lambda w, real: w & real  # noqa: E731
    return data, take, weight_of


def as_float(obs):
    """A minibatch's observations (``minibatch_source``'s, or with a memory the tuple
    they lead) as the networks take them: float32."""
    if isinstance(obs, tuple):
        return (obs[0].astype(jnp.float32),) + obs[1:]
    return obs.astype(jnp.float32)


def ppo_update(config: PPOConfig, network_for, optimizer, state: PolicyGradientState,
               traj: Transition, key: jax.Array):
    """``update_epochs`` passes over the rollout's complete decisions in minibatches."""
    traj = jax.tree.map(jnp.asarray, traj)  # numpy inputs too
    memory = config.recurrent_size
    num_envs = traj.reward.shape[1]
    # Train on complete decisions; a pending one returns in the next rollout (smdp.py).
    fields, episodes = decision_data(config, traj, state.hp)
    data, take, weight_of = minibatch_source(traj, fields, memory)
    loss_fn = functools.partial(ppo_loss, config, network_for)

    def minibatch_step(carry, mb):
        params, opt_state, grad_steps, stopped = carry
        idx, real = mb
        batch = jax.tree.map(lambda x: take(x, idx), data)
        batch = (as_float(batch[0]),) + batch[1:-1] + (weight_of(batch[-1], real),)
        (total, aux), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, batch, state.hp)
        updates, new_opt_state = optimizer.update(grads, opt_state, params)
        updates = scale_by_lr(updates, state.hp["learning_rate"])
        new_params = optax.apply_updates(params, updates)
        has_decision = jnp.any(batch[-1])
        stopped = kl_stop(stopped, has_decision, aux["approx_kl"], state.hp)
        step = has_decision & ~stopped
        params, opt_state = apply_if(step, (new_params, new_opt_state), (params, opt_state))
        aux = dict(aux, total_loss=total, counted=has_decision.astype(jnp.float32))
        return (params, opt_state, grad_steps + step.astype(jnp.int32), stopped), aux

    def epoch_step(carry, epoch_key):
        # environments are dealt like ticks whose every one holds a decision
        deal = jnp.ones((num_envs,), bool) if memory else data[-1]
        idx, real = minibatch_indices(epoch_key, deal, config.num_minibatches)
        return jax.lax.scan(minibatch_step, carry, (idx, real))

    carry = (state.params, state.opt_state, state.grad_steps, jnp.zeros((), bool))
    epoch_keys = jax.random.split(key, config.update_epochs)
    (params, opt_state, grad_steps, stopped), aux = jax.lax.scan(epoch_step, carry, epoch_keys)
    return finish(state, params, opt_state, grad_steps, stopped, aux, episodes, fields)
