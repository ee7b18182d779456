"""``Environment.contract_state``: the part of a state two programs must agree on.

A physics engine's forces and accelerations amplify float32 rounding in positions (Fetch's
servos: 1e-8 m becomes 3e-4 N), so jit vs eager and vmap vs loop compare the state that
determines them instead; the environment says which part that is.
"""
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax.numpy as jnp
import pytest
from flax import struct
from jax.custom_batching import custom_vmap

from envs_for_tests import Corridor
from smjax.testing import check_env

SMALL = dict(num_envs=4, steps=16)


@custom_vmap
def _rounded_differently(x):
    return x


@_rounded_differently.def_vmap
def _rounded_differently_batched(axis_size, in_batched, x):
    return x + 1e-3, in_batched[0]  # as a stiff servo's force differs between two programs


@struct.dataclass
class ForceState:
    inner: object
    force: jnp.ndarray


class ForceCorridor(Corridor):
    """The corridor's state plus a derived force that differs under vmap."""

    def reset_env(self, key, params):
        obs, state = super().reset_env(key, params)
        return obs, ForceState(state, jnp.float32(0.0))

    def step_env(self, key, state, action, params):
        obs, inner, reward, term, trunc, info = super().step_env(key, state.inner, action, params)
        force = _rounded_differently(inner.position.astype(jnp.float32))
        return obs, ForceState(inner, force), reward, term, trunc, info


class DeclaredForceCorridor(ForceCorridor):
    def contract_state(self, state):
        return state.inner  # the force is computed from the position


def test_a_derived_leaf_fails_unless_the_environment_leaves_it_out():
    env = ForceCorridor()
    with pytest.raises(AssertionError, match=r"vmap == loop failed for tests/corridor: .*"
                                             r"leaf \[1\]\.force"):
        check_env(env, env.default_params, **SMALL)
    env = DeclaredForceCorridor()
    check_env(env, env.default_params, **SMALL)
