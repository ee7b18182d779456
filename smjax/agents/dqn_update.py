"""The pieces of DQN's update that a single learner's update (``dqn.make_agent``) and
every option's at once (``dqn_options``) share: the replay buffer, turning a rollout
into its rows, and the gradient steps with the update's metrics (the algorithm: ``dqn``)."""
from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp

from smjax.agents.base import Transition
from smjax.agents.smdp import episodes_with_decision, smdp_transitions


@flax.struct.dataclass
class ReplayBuffer:
    obs: jax.Array          # [C, *obs_shape], the observation dtype
    action: jax.Array       # [C] int32
    reward: jax.Array       # [C] SMDP reward sum
    discount: jax.Array     # [C] product of the tick discounts until the next decision
    terminal: jax.Array     # [C] bool
    next_obs: jax.Array     # [C, *obs_shape]
    next_mask: jax.Array    # [C, A] bool
    size: jax.Array         # int32 scalar
    insert_pos: jax.Array   # int32 scalar, next slot to write


def linear_epsilon(config, hp: dict, grad_steps: jax.Array,
                   decisions_seen: jax.Array) -> jax.Array:
    progress = grad_steps if config.epsilon_schedule_unit == "gradient_steps" else decisions_seen
    frac = jnp.clip(progress.astype(jnp.float32) / hp["epsilon_decay_steps"], 0.0, 1.0)
    return config.epsilon_start + frac * (hp["epsilon_end"] - config.epsilon_start)


def insert(buffer: ReplayBuffer, items: dict, valid: jax.Array) -> ReplayBuffer:
    """Write the ``valid`` rows of ``items`` (leading axis N) at the circular write position.

    With more valid rows than capacity only the last ``capacity`` are kept, so every write
    position is distinct and the result does not depend on scatter order.
    """
    capacity = buffer.action.shape[0]
    valid = valid.astype(bool)
    rank = jnp.cumsum(valid.astype(jnp.int32)) - 1
    count = valid.sum().astype(jnp.int32)
    keep = jnp.logical_and(valid, rank >= count - capacity)
    pos = jnp.where(keep, (buffer.insert_pos + rank) % capacity, capacity)  # capacity = dropped
    written = {
        name: getattr(buffer, name).at[pos].set(value.astype(getattr(buffer, name).dtype), mode="drop")
        for name, value in items.items()
    }
    return buffer.replace(
        **written,
        size=jnp.minimum(buffer.size + count, capacity),
        insert_pos=(buffer.insert_pos + count) % capacity,
    )


def empty_buffer(capacity: int, example_obs: jax.Array, num_actions: int) -> ReplayBuffer:
    """A replay buffer of ``capacity`` zero rows, every next action allowed."""
    obs_buf = jnp.zeros((capacity,) + example_obs.shape, example_obs.dtype)
    return ReplayBuffer(
        obs=obs_buf, action=jnp.zeros((capacity,), jnp.int32),
        reward=jnp.zeros((capacity,), jnp.float32), discount=jnp.zeros((capacity,), jnp.float32),
        terminal=jnp.zeros((capacity,), bool), next_obs=obs_buf,
        next_mask=jnp.ones((capacity, int(num_actions)), bool),
        size=jnp.zeros((), jnp.int32), insert_pos=jnp.zeros((), jnp.int32),
    )


def rollout_items(state, traj: Transition):
    """A rollout's SMDP transitions as buffer rows: ``(state, items, valid, decisions)``,
    the state's counters advanced, ``items`` the rows ``[T * B]`` (``obs`` and
    ``next_obs`` whatever ``traj.obs`` holds: observations, or rows of a table of them),
    ``valid`` the complete decisions among them and ``decisions`` their number."""
    traj = jax.tree.map(jnp.asarray, traj)  # numpy inputs too
    num_ticks, num_envs = traj.reward.shape[:2]
    num_items = num_ticks * num_envs
    decision = traj.decision.astype(bool)
    tr = smdp_transitions(traj.reward, traj.discount, traj.done, decision,
                          traj.obs, traj.action_mask)
    flat = lambda x: x.reshape((num_items,) + x.shape[2:])  # noqa: E731
    items = {"obs": flat(traj.obs), "action": flat(traj.action),
             "reward": flat(tr.reward) * state.hp["reward_scale"], "discount": flat(tr.discount),
             "terminal": flat(tr.terminal), "next_obs": flat(tr.next_obs),
             "next_mask": flat(tr.next_mask)}
    num_decisions = tr.valid.sum().astype(jnp.int32)  # each counted once, when complete
    state = state.replace(
        decisions_seen=state.decisions_seen + num_decisions,
        episodes_seen=state.episodes_seen + episodes_with_decision(traj.done, decision),
        updates=state.updates + 1,
    )
    return state, items, flat(tr.valid), num_decisions


def train_steps(config, step, state, key: jax.Array,
                num_decisions: jax.Array):
    """``gradient_steps_per_update`` ``step``s on the buffer: (state, the update's metrics)."""
    keys = jax.random.split(key, config.gradient_steps_per_update)
    state, step_metrics = jax.lax.scan(step, state, keys)
    stepped = step_metrics.pop("stepped")
    denom = jnp.maximum(stepped.sum(), 1.0)
    metrics = {name: jnp.sum(v * stepped) / denom for name, v in step_metrics.items()}
    metrics.update(
        decisions=num_decisions,
        buffer_size=state.buffer.size,
        epsilon=linear_epsilon(config, state.hp, state.grad_steps, state.decisions_seen),
        episodes_seen=state.episodes_seen,
        grad_steps=state.grad_steps,
    )
    return state, metrics


def dqn_update(config, step, state, traj: Transition, key: jax.Array):
    """Store the rollout's complete decisions, then ``gradient_steps_per_update`` ``step``s."""
    state, items, valid, num_decisions = rollout_items(state, traj)
    state = state.replace(buffer=insert(state.buffer, items, valid))
    return train_steps(config, step, state, key, num_decisions)
