"""A small real environment with option templates, used to test the option machinery
independently of Craft: a 1-D corridor with a key and a door.

Cells 0..N-1. Actions: LEFT 0, RIGHT 1, USE 2. USE on the key's cell picks the key up;
USE on the door's cell while holding the key opens it (reward 1, terminated). Step cap.
Template ``give_key`` (satisfied: key held) teleports next to... onto the key's cell and
USEs; ``walk_right`` is a scripted controller that walks right for the door's side.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from smjax.core import Environment, spaces
from smjax.options import OptionTemplate, declare

N = 8


@struct.dataclass
class KDState:
    pos: jax.Array
    key_pos: jax.Array
    door_pos: jax.Array
    has_key: jax.Array
    opened: jax.Array
    t: jax.Array


@struct.dataclass
class KDParams:
    max_steps: int = 30


class KeyDoor(Environment):
    name = "test/keydoor"

    @property
    def default_params(self):
        return KDParams()

    def reset_env(self, key, params):
        k1, k2, k3 = jax.random.split(key, 3)
        # key in the left half, door in the right half, agent anywhere
        state = KDState(
            pos=jax.random.randint(k1, (), 0, N),
            key_pos=jax.random.randint(k2, (), 0, N // 2),
            door_pos=jax.random.randint(k3, (), N // 2, N),
            has_key=jnp.asarray(False), opened=jnp.asarray(False), t=jnp.asarray(0),
        )
        return self.get_obs(state, params), state

    def step_env(self, key, state, action, params):
        move = jnp.where(action == 0, -1, jnp.where(action == 1, 1, 0))
        pos = jnp.clip(state.pos + move, 0, N - 1)
        use = action == 2
        has_key = state.has_key | (use & (state.pos == state.key_pos))
        opened = state.opened | (use & state.has_key & (state.pos == state.door_pos))
        t = state.t + 1
        new = KDState(pos, state.key_pos, state.door_pos, has_key, opened, t)
        reward = (opened & ~state.opened).astype(jnp.float32)
        terminated = opened
        truncated = (t >= params.max_steps) & ~terminated
        return self.get_obs(new, params), new, reward, terminated, truncated, {}

    def get_obs(self, state, params):
        return jnp.concatenate([
            jax.nn.one_hot(state.pos, N), jax.nn.one_hot(state.key_pos, N),
            jax.nn.one_hot(state.door_pos, N), state.has_key[None].astype(jnp.float32),
        ])

    def action_space(self, params=None):
        return spaces.Discrete(3)

    def observation_space(self, params=None):
        return spaces.Box(0.0, 1.0, (3 * N + 1,))

    @property
    def primitive_action_names(self):
        return ("left", "right", "use")

    def templates(self):
        def teleport_to_key(key, state, params):
            return state.replace(pos=state.key_pos), jnp.asarray(2)

        def walk_to_door(key, state, params):
            return jnp.where(state.pos < state.door_pos, 1, 0)

        return {
            "give_key": OptionTemplate(
                name="give_key", satisfied=lambda s, p: s.has_key, k_max=12,
                initiation=lambda s, p: ~s.has_key, teleport=teleport_to_key, nominal_steps=4),
            "reach_door": OptionTemplate(
                name="reach_door", satisfied=lambda s, p: s.pos == s.door_pos, k_max=12,
                initiation=lambda s, p: s.pos != s.door_pos, controller=walk_to_door),
        }

    def hierarchies(self):
        return {
            "paper": declare(self, "open_door", {"open_door": ["give_key", "primitives"],
                                                 "give_key": ["primitives"]}),
            "scripted": declare(self, "open_door", {"open_door": ["give_key", "reach_door", "use"],
                                                    "give_key": ["primitives"]}),
            "flat": declare(self, "open_door", {"open_door": ["primitives"]}),
        }


def make_keydoor():
    env = KeyDoor()
    return env, env.default_params
