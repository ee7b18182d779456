"""Per-seed array operations of the host loop (leading axis = seed), jitted once each.

Seeds train at their own pace, so the loop often changes some seeds' state and keeps the
others': these compute for every seed and select, so that every call has the same shapes
(one compile per run, however many seeds change at once).
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from smjax.train import distributed as dist


@functools.partial(jax.jit, static_argnums=1)
def split_seeds(keys: jax.Array, n: int) -> tuple[jax.Array, ...]:
    """Each seed's key split in ``n``: n arrays of keys [S]."""
    split = jax.vmap(lambda k: jax.random.split(k, n))(keys)
    return tuple(split[:, i] for i in range(n))


@jax.jit
def fold_in(keys: jax.Array, data: jax.Array) -> jax.Array:
    """Each seed's key folded with the same ``data``."""
    return jax.vmap(jax.random.fold_in, (0, None))(keys, data)


@jax.jit
def select_seeds(mask: jax.Array, new, old):
    """Per seed (leading axis), ``new`` where ``mask`` else ``old``."""
    def pick(a, b):
        return jnp.where(mask.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)
    return jax.tree.map(pick, new, old)


@jax.jit
def freeze(mask: jax.Array, options: jax.Array, params, bank, learned):
    """Store each masked seed's learner params in its bank at its option; mark it learned."""
    rows = jnp.arange(mask.shape[0])

    def store(b, p):
        keep = b[rows, options]
        return b.at[rows, options].set(jnp.where(mask.reshape((-1,) + (1,) * (p.ndim - 1)), p, keep))

    learned = learned.at[rows, options].set(learned[rows, options] | mask)
    return jax.tree.map(store, bank, params), learned


class NonFiniteError(FloatingPointError):
    """A learner produced non-finite parameters (``run`` says which checkpoint is kept)."""


def finite_flag(tree) -> jax.Array:
    """bool []: every floating leaf of ``tree`` is finite (traced inside a chunk, so the
    check costs no program of its own)."""
    flags = [jnp.isfinite(x).all() for x in jax.tree.leaves(tree)
             if jnp.issubdtype(x.dtype, jnp.floating)]
    return jnp.stack(flags).all() if flags else jnp.asarray(True)


def local(x: jax.Array) -> jax.Array:
    """``x`` as an array this process holds whole (host-side derivations such as key
    splits and learner inits work on it; they are then placed on the mesh again)."""
    return x if x.is_fully_addressable else jnp.asarray(dist.gather(x))


def final_evaluation_keys(keys: jax.Array) -> jax.Array:
    """The keys [S] of the final evaluation (``final_success``), from each seed's key at
    the end of training: a saved policy keeps them, so evaluating it reproduces that
    figure."""
    return split_seeds(local(keys), 2)[1]
