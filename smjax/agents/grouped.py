"""Gradients of every option's loss at once, at the cost of the rows each option has.

A learner per option (parameters stacked on a leading axis O) trains on its own rows of
a batch. Running every option's network over every row and masking the others' out
costs rows x options; here each option's rows are cut into blocks of ``block`` rows
(the last one padded), and a loop runs one block at a time through its own option's
parameters, adding the block's gradient to that option's. The loop runs as many times
as there are blocks, a traced count, so the work follows the rows there are (plus at
most one padded block per option), not a static worst case. Under ``vmap`` (seeds) the
loop runs as often as the seed with the most blocks needs.

Why blocks and not ``jax.lax.ragged_dot``: on XLA:CPU a ragged product over 5 groups
takes longer than the dense product of every row with every group's weights.
"""
from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp


def block_count(counts: jax.Array, block: int) -> jax.Array:
    """int [O]: the blocks each option's ``counts`` rows fill."""
    return (counts + block - 1) // block


def grouped_grads(block_loss: Callable, params: Any, counts: jax.Array,
                  block: int) -> tuple[Any, dict]:
    """Every option's gradient and summed auxiliary values over its own rows.

    ``params``: stacked per option (leading axis O); ``counts`` int [O]: option o's rows
    are its rows 0 .. counts[o] - 1. ``block_loss(option_params, o, rows, valid) ->
    (loss, aux)`` is option o's loss on ``rows`` (int [block]; ``valid``: bool [block],
    False past its count), a part of a sum over its blocks (padding rows must add
    nothing); ``aux`` is a dict of scalars. Returns the grads (stacked like ``params``)
    and the sum per option ([O]) of the loss (``"loss"``) and of each aux value."""
    num_options = counts.shape[0]
    blocks = block_count(counts, block)
    ends = jnp.cumsum(blocks)
    rows = jnp.arange(block, dtype=counts.dtype)
    grad_fn = jax.value_and_grad(block_loss, has_aux=True)

    def body(carry):
        i, grads, sums = carry
        o = jnp.sum(ends <= i).astype(jnp.int32)  # the option whose blocks cover block i
        j = (i - (ends[o] - blocks[o])) * block + rows
        mine = jnp.arange(num_options) == o
        own = jax.tree.map(lambda x: _pick(mine, x), params)
        (loss, aux), g = grad_fn(own, o, j, j < counts[o])
        grads = jax.tree.map(lambda acc, x: acc + _spread(mine, x), grads, g)
        sums = jax.tree.map(lambda acc, x: acc + _spread(mine, x), sums, dict(aux, loss=loss))
        return i + 1, grads, sums

    zeros = jax.tree.map(jnp.zeros_like, params)
    own = jax.tree.map(lambda x: x[0], params)
    loss, aux = jax.eval_shape(block_loss, own, jnp.int32(0), rows, rows < 0)
    sums = jax.tree.map(lambda x: jnp.zeros((num_options,), x.dtype), dict(aux, loss=loss))
    init = (jnp.zeros((), counts.dtype), zeros, sums)
    _, grads, sums = jax.lax.while_loop(lambda c: c[0] < ends[-1], body, init)
    return grads, sums


# Selecting an option's parameters and adding to its gradient by a one-hot product
# rather than an index: under ``vmap`` (seeds) an index becomes a gather or a scatter,
# which XLA:CPU runs element by element; the products are dense and cheap (O is small).
def _pick(mine: jax.Array, stacked: jax.Array) -> jax.Array:
    """``stacked[o]`` for the one-hot ``mine`` [O]."""
    return jnp.tensordot(mine.astype(stacked.dtype), stacked, axes=1)


def _spread(mine: jax.Array, x: jax.Array) -> jax.Array:
    """``x`` at option o of a stacked ``[O, ...]`` zero, for the one-hot ``mine``."""
    return mine.astype(x.dtype).reshape((-1,) + (1,) * x.ndim) * x
