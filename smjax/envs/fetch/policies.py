"""Scripted policies of the stacking hierarchy's options (``Hierarchy.policies``).

With them the runner plays the paper's hierarchy entirely by hand, as a hierarchy:
``stack`` calls ``place_i`` for the lowest block not in place (a tower is built bottom
up; ``noop`` once every block is), and ``place_i`` calls ``release_i`` once block i is
on its goal, ``pick_i`` once it is reached or held, else ``reach_i``; every option runs
until its termination test or its k_max, as the runner runs any option. The catalogue's
``scripted`` and ``scripted_root`` hierarchies (``templates.make_hierarchies``) use them.

Both rules read only the children's mask (what the option may call now), which holds
exactly the tests they need: ``place_i`` may be called while block i is not in place,
``pick_i`` once block i is reached or held, ``release_i`` once it is on its goal.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp


def stack_policy(num_blocks: int, epsilon: float = 0.0):
    """The root's rule over ``[place_0 .. place_{N-1}, noop]`` (or ``hold`` last).

    With ``epsilon`` > 0 it explores like a DQN root: with probability ``epsilon`` it calls
    ``place_i`` of a uniformly drawn block not in place instead of the lowest one (the
    score an optimal but exploring root reaches: the ceiling of a learner's running score).
    """
    if not isinstance(epsilon, (int, float)) or not 0.0 <= float(epsilon) <= 1.0:
        raise ValueError(f"epsilon must be a number in [0, 1], got {epsilon!r}")
    n, epsilon = int(num_blocks), float(epsilon)

    def policy(key: jax.Array, state, params, mask: jax.Array) -> jax.Array:
        free = mask[:n]  # place_i may run: block i is not in place
        block = jnp.argmax(free)
        if epsilon > 0.0:  # a fixed 0 draws nothing
            k_explore, k_block = jax.random.split(key)
            drawn = jax.random.categorical(k_block, jnp.where(free, 0.0, -jnp.inf))
            block = jnp.where(jax.random.uniform(k_explore) < epsilon, drawn, block)
        return jnp.where(free.any(), block, n).astype(jnp.int32)

    return policy


def place_policy(key: jax.Array, state, params, mask: jax.Array) -> jax.Array:
    """``place_i``'s rule over ``[reach_i, pick_i, release_i, noop]``: release once the
    block is on its goal, pick once it is reached or held, else reach."""
    return jnp.where(mask[2], 2, jnp.where(mask[1], 1, 0)).astype(jnp.int32)
