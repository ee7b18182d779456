"""Small real smjax Environments for the learner tests.

``Corridor``: cells 0 .. length-1, start at 0; actions LEFT 0, RIGHT 1, STAY 2. Reaching
the right end gives reward 1 and ends the episode; ``max_steps`` truncates. A uniformly
random policy drifts left (only one action of three moves right), so it rarely reaches
the end within the cap, while the optimal policy always does in ``length - 1`` steps.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from smjax.agents.base import Transition
from smjax.agents.smdp import carry_pending, no_pending
from smjax.core import Environment, spaces


@struct.dataclass
class CorridorState:
    position: jax.Array
    time: jax.Array


@struct.dataclass
class CorridorParams:
    max_steps: int = 12


class Corridor(Environment[CorridorState, CorridorParams]):
    LEFT, RIGHT, STAY = 0, 1, 2

    def __init__(self, length: int = 6):
        if length < 2:
            raise ValueError(f"Corridor length must be >= 2, got {length}")
        self.length = length
        self.name = "tests/corridor"

    @property
    def default_params(self) -> CorridorParams:
        return CorridorParams()

    def reset_env(self, key, params):
        state = CorridorState(jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32))
        return self.get_obs(state, params), state

    def step_env(self, key, state, action, params):
        move = jnp.where(action == self.LEFT, -1, jnp.where(action == self.RIGHT, 1, 0))
        position = jnp.clip(state.position + move, 0, self.length - 1)
        state = CorridorState(position, state.time + 1)
        at_goal = position == self.length - 1
        reward = at_goal.astype(jnp.float32)
        truncated = jnp.logical_and(state.time >= params.max_steps, jnp.logical_not(at_goal))
        return self.get_obs(state, params), state, reward, at_goal, truncated, {}

    def get_obs(self, state, params):
        # uint8 on purpose: the learners must cast observations themselves.
        return jax.nn.one_hot(state.position, self.length, dtype=jnp.uint8)

    def action_space(self, params=None):
        return spaces.Discrete(3)

    def observation_space(self, params=None):
        return spaces.Box(0, 1, (self.length,), jnp.uint8)


# ---- an SMDP driver: the learner calls options that run several ticks ----------------
#
# A stand-in for the hierarchical trainer. Each learner decision picks one of three
# options with different durations and per-tick discounts; the other ticks are
# non-decision ticks, and every episode starts with 0..2 ticks before the learner's first
# decision. With gamma = 0.5:
#   option 0: 1 tick, reward 1                       Q ~ 1 + 0.5 V        (best)
#   option 1: 5 ticks, reward 0.3 on each tick       Q ~ 0.58 + 0.03 V    (1.5 undiscounted!)
#   option 2: 1 tick teleport, reward 1.2, discount gamma**10  Q ~ 1.2 + 0.001 V
# A learner that ignored the tick discounts inside an option or the teleport discount
# would prefer option 1 or 2; only correct SMDP returns make option 0 the best (except
# on the episode's last tick, where the future is worth nothing).

OPTION_DURATION = (1, 5, 1)
OPTION_TICK_REWARD = (1.0, 0.3, 1.2)
TELEPORT_STEPS = 10
EPISODE_TICKS = 12
MAX_DELAY = 2
SMDP_GAMMA = 0.5


@struct.dataclass
class OptionDriverState:
    tick: jax.Array        # [B] ticks into the episode
    option: jax.Array      # [B] option running
    remaining: jax.Array   # [B] ticks left of that option
    delay: jax.Array       # [B] ticks left before the learner's first decision
    mask: jax.Array        # [B, 3] options allowed at the next decision


def option_observation(tick: jax.Array) -> jax.Array:
    return jnp.stack([jnp.ones_like(tick, jnp.float32), tick / EPISODE_TICKS], -1)


def _random_masks(key, num_envs):
    allowed = jax.random.uniform(key, (num_envs, 3)) < jnp.array([0.7, 0.8, 0.8])
    none = ~jnp.any(allowed, -1, keepdims=True)
    return jnp.logical_or(allowed, jnp.logical_and(none, jnp.array([False, True, False])))


def make_option_driver_train(agent, num_envs: int, num_ticks: int, num_updates: int):
    """``train(key) -> (agent_state, metrics)`` over the option driver; pure and jittable.

    metrics per update: ``chose_option0`` (fraction of decisions with option 0 allowed that
    chose it) and ``masked_violations`` (decisions that picked a disallowed option).
    """
    duration = jnp.array(OPTION_DURATION, jnp.int32)
    tick_reward = jnp.array(OPTION_TICK_REWARD, jnp.float32)

    def reset(key, state=None):
        k_delay, k_mask = jax.random.split(key)
        return OptionDriverState(
            tick=jnp.zeros((num_envs,), jnp.int32), option=jnp.zeros((num_envs,), jnp.int32),
            remaining=jnp.zeros((num_envs,), jnp.int32),
            delay=jax.random.randint(k_delay, (num_envs,), 0, MAX_DELAY + 1),
            mask=_random_masks(k_mask, num_envs))

    def tick_fn(carry, _):
        agent_state, s, key = carry
        key, k_act, k_mask, k_reset = jax.random.split(key, 4)
        obs = option_observation(s.tick)
        decide = jnp.logical_and(s.remaining == 0, s.delay == 0)
        out = agent.act(agent_state, obs, s.mask, k_act)
        option = jnp.where(decide, out.action, s.option)
        in_delay = s.delay > 0
        reward = jnp.where(in_delay, 0.0, tick_reward[option])
        teleport = jnp.logical_and(~in_delay, option == 2)
        discount = jnp.where(teleport, SMDP_GAMMA**TELEPORT_STEPS, SMDP_GAMMA)
        remaining = jnp.where(in_delay, 0, jnp.where(decide, duration[option], s.remaining) - 1)
        tick = s.tick + 1
        done = tick >= EPISODE_TICKS
        fresh = reset(k_reset)
        new = OptionDriverState(tick, option, remaining, jnp.maximum(s.delay - 1, 0),
                                _random_masks(k_mask, num_envs))
        new = jax.tree.map(lambda a, b: jnp.where(done.reshape(done.shape + (1,) * (a.ndim - 1)), a, b),
                           fresh, new)
        picked_allowed = jnp.take_along_axis(s.mask, out.action[:, None], -1)[:, 0]
        transition = Transition(obs, out.action, s.mask, out.log_prob, out.value, decide,
                                reward, discount, done)
        stats = (decide & s.mask[:, 0], decide & s.mask[:, 0] & (out.action == 0),
                 decide & ~picked_allowed)
        return (agent_state, new, key), (transition, stats)

    def update_fn(carry, _):
        agent_state, s, pending, key = carry
        (agent_state, s, key), (traj, stats) = jax.lax.scan(
            tick_fn, (agent_state, s, key), None, num_ticks)
        key, k_update = jax.random.split(key)
        traj, pending = carry_pending(pending, traj)
        agent_state, metrics = agent.update(agent_state, traj, k_update)
        could, chose, violated = stats
        metrics = dict(metrics, chose_option0=chose.sum() / jnp.maximum(could.sum(), 1),
                       masked_violations=violated.sum())
        return (agent_state, s, pending, key), metrics

    def train(key):
        key, k_init, k_reset = jax.random.split(key, 3)
        state = reset(k_reset)
        agent_state = agent.init(k_init, option_observation(state.tick)[0], 3)
        pending = no_pending(option_observation(state.tick), 3)
        (agent_state, *_), metrics = jax.lax.scan(update_fn, (agent_state, state, pending, key),
                                                  None, num_updates)
        return agent_state, metrics

    return train
