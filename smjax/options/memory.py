"""A one-step memory in the policies' input: the last primitive action and whether it
changed the observation.

Why: on Craft a memoryless policy that picks greedily repeats itself forever where a move
is blocked (the observation, and so the pick, stays the same), so the learned options rely
on sampling to get out, and the same sampling picks up stray items. With the last action
and a "nothing changed" bit in its input, a policy can tell a blocked move from a fresh
state and choose otherwise without chance. It helps greedy execution, not the sampled
success PPO reports, so it is an option, off by default.

Generic: it reads only the observation array and the primitive action the tick executed
(whichever option chose it, or a controller or teleport), never the environment's state.
The policies see ``[flattened observation, memory]``; templates, rewards and the
environment itself are untouched. After a reset the memory part is all zeros.
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from smjax.core.spaces import Discrete

POLICY_MEMORIES = ("none", "last_action")


class LastAction:
    """Appends ``[one-hot (or Box: the values) of the last primitive action, moved]`` to
    each flattened observation (leading axis B); ``moved`` is 1 where the observation
    differs from the one before the action."""

    def __init__(self, action_space, raw_obs):
        """``raw_obs``: one observation (an array, or its ``jax.ShapeDtypeStruct``)."""
        self.discrete = isinstance(action_space, Discrete) and tuple(action_space.shape) == ()
        self.num_actions = action_space.n if self.discrete else None
        action_width = self.num_actions if self.discrete else math.prod(action_space.shape)
        self.raw_width = math.prod(raw_obs.shape)
        self.width = action_width + 1
        # 0/1 values keep a discrete action's memory in the observation's own dtype
        # (Craft's observation is not float); a Box action's values need floats
        self.dtype = raw_obs.dtype if self.discrete else jnp.float32

    def start(self, raw_obs: jax.Array) -> jax.Array:
        """[B, F + width]: fresh episodes, nothing remembered."""
        flat = self._flat(raw_obs)
        return jnp.concatenate([flat, jnp.zeros((flat.shape[0], self.width), self.dtype)], -1)

    def after(self, previous: jax.Array, raw_obs: jax.Array, action: jax.Array) -> jax.Array:
        """[B, F + width]: the observation after ``action`` ([B, ...]), ``previous`` being
        the policies' input before it (this module's layout)."""
        flat = self._flat(raw_obs)
        moved = jnp.any(flat != previous[:, :self.raw_width], axis=-1)
        if self.discrete:
            last = jax.nn.one_hot(action.reshape(-1), self.num_actions, dtype=self.dtype)
        else:
            last = action.reshape(action.shape[0], -1)
        return jnp.concatenate([flat, last.astype(self.dtype),
                                moved[:, None].astype(self.dtype)], -1)

    def _flat(self, raw_obs: jax.Array) -> jax.Array:
        return raw_obs.reshape(raw_obs.shape[0], -1).astype(self.dtype)


def make_memory(kind: str, action_space, raw_obs) -> LastAction | None:
    """The policy memory named ``kind`` (None for "none"); ``raw_obs``: one observation, or
    a function returning it (called only where a memory needs its shape)."""
    if kind not in POLICY_MEMORIES:
        raise ValueError(f"policy_memory must be one of {POLICY_MEMORIES}, got {kind!r}")
    if kind == "none":
        return None
    return LastAction(action_space, raw_obs() if callable(raw_obs) else raw_obs)
