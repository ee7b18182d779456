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
