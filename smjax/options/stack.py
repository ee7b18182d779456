"""The option execution stack as fixed-depth arrays.

Per environment: ``option[D]`` (int32, -1 where empty), ``steps[D]`` (ticks each entry
has run) and ``depth`` (number of entries). Push, pop and top are index updates with
no Python control flow on traced values, so the stack vmaps over environments.
Pushing onto a full stack is ignored (the hierarchy's depth bounds it; see
``Hierarchy.stack_depth``), popping an empty stack is ignored.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

EMPTY = -1


@struct.dataclass
class ExecutionStack:
    option: jax.Array  # int32 [D]
    steps: jax.Array   # int32 [D]
    depth: jax.Array   # int32 []

    @property
    def capacity(self) -> int:
        return self.option.shape[-1]


def stack_init(capacity: int, bottom: jax.Array | int = 0) -> ExecutionStack:
    """A stack holding only ``bottom`` (the root option, or a learner started directly)."""
    option = jnp.full((capacity,), EMPTY, jnp.int32).at[0].set(jnp.asarray(bottom, jnp.int32))
    return ExecutionStack(option, jnp.zeros((capacity,), jnp.int32), jnp.asarray(1, jnp.int32))


def stack_top(stack: ExecutionStack) -> jax.Array:
    """Option id on top, or EMPTY for an empty stack."""
    return jnp.where(stack.depth > 0, stack.option[jnp.maximum(stack.depth - 1, 0)], EMPTY)


def stack_push(stack: ExecutionStack, option: jax.Array, when: jax.Array | bool = True) -> ExecutionStack:
    """Push ``option`` (with 0 steps) if ``when`` and there is room."""
    ok = jnp.logical_and(jnp.asarray(when), stack.depth < stack.capacity)
    # The new slot as a mask, not an indexed write: vmapped, an indexed write is a scatter,
    # its own kernel and a copy of the stack on a GPU, every push of every tick.
    at = ok & (jnp.arange(stack.capacity) == stack.depth)
    return ExecutionStack(jnp.where(at, jnp.asarray(option, jnp.int32), stack.option),
                          jnp.where(at, 0, stack.steps), stack.depth + ok.astype(jnp.int32))


def stack_truncate(stack: ExecutionStack, new_depth: jax.Array) -> ExecutionStack:
    """Pop every entry at position >= ``new_depth`` (no-op if new_depth >= depth)."""
    new_depth = jnp.clip(jnp.minimum(new_depth, stack.depth), 0, stack.capacity)
    keep = jnp.arange(stack.capacity) < new_depth
    return ExecutionStack(
        jnp.where(keep, stack.option, EMPTY), jnp.where(keep, stack.steps, 0), new_depth.astype(jnp.int32)
    )


def stack_pop(stack: ExecutionStack, when: jax.Array | bool = True) -> ExecutionStack:
    """Pop the top entry if ``when`` (and the stack is not empty)."""
    return stack_truncate(stack, jnp.where(jnp.asarray(when), stack.depth - 1, stack.depth))


def stack_tick(stack: ExecutionStack) -> ExecutionStack:
    """Count one tick for every live entry."""
    live = jnp.arange(stack.capacity) < stack.depth
    return stack.replace(steps=stack.steps + live.astype(jnp.int32))


def stack_contains(stack: ExecutionStack, option: jax.Array) -> jax.Array:
    live = jnp.arange(stack.capacity) < stack.depth
    return jnp.any(jnp.logical_and(live, stack.option == option))


def stack_members(stack: ExecutionStack, num_options: int) -> jax.Array:
    """bool [num_options]: the options on the stack."""
    live = jnp.arange(stack.capacity) < stack.depth
    return jnp.any(live[:, None] & (stack.option[:, None] == jnp.arange(num_options)), axis=0)


def options_on(stack: ExecutionStack, num_options: int) -> jax.Array:
    """bool [B, num_options]: the options on each stack of a batch (leading axis B)."""
    return jax.vmap(lambda st: stack_members(st, num_options))(stack)
