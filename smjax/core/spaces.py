"""Action and observation spaces (gymnax-style, jittable sampling)."""
from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp


class Space:
    """Base class: a set of values with a fixed shape and dtype."""

    shape: tuple[int, ...]
    dtype: jnp.dtype

    def sample(self, key: jax.Array) -> jax.Array:
        raise NotImplementedError

    def contains(self, x: jax.Array) -> jax.Array:
        """Traceable bool: every element of ``x`` lies in the set (NaN never does)."""
        raise NotImplementedError


class Discrete(Space):
    """Integers 0 .. n-1, optionally several independent ones (shape != ())."""

    def __init__(self, n: int, shape: Sequence[int] = (), dtype=jnp.int32):
        if int(n) < 1:
            raise ValueError(f"Discrete space needs n >= 1, got {n}")
        self.n = int(n)
        self.shape = tuple(shape)
        self.dtype = dtype

    def sample(self, key: jax.Array) -> jax.Array:
        return jax.random.randint(key, self.shape, 0, self.n).astype(self.dtype)

    def contains(self, x: jax.Array) -> jax.Array:
        x = jnp.asarray(x)
        inside = jnp.logical_and(jnp.all(x >= 0), jnp.all(x < self.n))
        if jnp.issubdtype(x.dtype, jnp.integer):
            return inside
        return jnp.logical_and(inside, jnp.all(x == jnp.floor(x)))  # 1.5 is no action

    def __repr__(self) -> str:
        return f"Discrete({self.n}, shape={self.shape})"


class Box(Space):
    """Real (or integer) arrays with element-wise bounds."""

    def __init__(self, low, high, shape: Sequence[int], dtype=jnp.float32):
        self.low = low
        self.high = high
        self.shape = tuple(shape)
        self.dtype = dtype

    def sample(self, key: jax.Array) -> jax.Array:
        low = jnp.broadcast_to(jnp.asarray(self.low, jnp.float32), self.shape)
        high = jnp.broadcast_to(jnp.asarray(self.high, jnp.float32), self.shape)
        finite_low = jnp.where(jnp.isfinite(low), low, -1.0)
        finite_high = jnp.where(jnp.isfinite(high), high, 1.0)
        u = jax.random.uniform(key, self.shape, minval=finite_low, maxval=finite_high)
        return u.astype(self.dtype)

    def contains(self, x: jax.Array) -> jax.Array:
        x = jnp.asarray(x)
        return jnp.logical_and(jnp.all(x >= self.low), jnp.all(x <= self.high))

    def __repr__(self) -> str:
        return f"Box(shape={self.shape}, dtype={jnp.dtype(self.dtype).name})"
