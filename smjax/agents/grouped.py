"""Gradients of every option's loss at once, at the cost of the rows each option has.

A learner per option (parameters stacked on a leading axis O) trains on its own rows of
a batch. Running every option's network over every row and masking the others' out
costs rows x options; here each option's rows are cut into blocks of ``block`` rows
(the last one padded), and a loop runs one block at a time through its own option's
parameters, adding the block's gradient to that option's. The loop runs as many times
as there are blocks, a traced count, so the work follows the rows there are (plus at
most one padded block per option), not a static worst case. Under ``vmap`` (seeds) the
loop runs as often as the seed with the most blocks needs. ``grouped_sums`` is the same
loop for values that need no gradient (a forward pass over the rows).

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
    grad_fn = jax.value_and_grad(block_loss, has_aux=True)

    def add_block(acc, own, o, j, valid, mine):
        grads, sums = acc
        (loss, aux), g = grad_fn(own, o, j, valid)
        grads = jax.tree.map(lambda a, x: a + _spread(mine, x), grads, g)
        sums = jax.tree.map(lambda a, x: a + _spread(mine, x), sums, dict(aux, loss=loss))
        return grads, sums

    def loss_and_aux(own, o, j, valid):
        loss, aux = block_loss(own, o, j, valid)
        return dict(aux, loss=loss)

    zeros = jax.tree.map(jnp.zeros_like, params)
    init = (zeros, _zero_sums(loss_and_aux, params, counts, block))
    return _block_loop(add_block, params, counts, block, init)


def grouped_sums(block_values: Callable, params: Any, counts: jax.Array, block: int) -> dict:
    """Every option's sums of ``block_values(option_params, o, rows, valid) -> dict of
    scalars`` over its own rows (as ``grouped_grads``, without a gradient): a pass that
    only reads the networks, at the price of a forward pass over the rows there are."""
    def add_block(sums, own, o, j, valid, mine):
        values = block_values(own, o, j, valid)
        return jax.tree.map(lambda a, x: a + _spread(mine, x), sums, values)

    init = _zero_sums(block_values, params, counts, block)
    return _block_loop(add_block, params, counts, block, init)


def _zero_sums(block_values: Callable, params: Any, counts: jax.Array, block: int) -> dict:
    """A zero [O] for each scalar that ``block_values`` gives."""
    rows = jnp.arange(block, dtype=counts.dtype)
    own = jax.tree.map(lambda x: x[0], params)
    values = jax.eval_shape(block_values, own, jnp.int32(0), rows, rows < 0)
    return jax.tree.map(lambda x: jnp.zeros((counts.shape[0],), x.dtype), values)


def _block_loop(add_block: Callable, params: Any, counts: jax.Array, block: int, init):
    """``add_block(acc, option_params, o, rows, valid, one_hot_o) -> acc`` over every
    block of every option's rows, one block at a time, from ``init``."""
    num_options = counts.shape[0]
    blocks = block_count(counts, block)
    ends = jnp.cumsum(blocks)
    rows = jnp.arange(block, dtype=counts.dtype)

    def body(carry):
        i, acc = carry
        o = jnp.sum(ends <= i).astype(jnp.int32)  # the option whose blocks cover block i
        j = (i - (ends[o] - blocks[o])) * block + rows
        mine = jnp.arange(num_options) == o
        own = jax.tree.map(lambda x: _pick(mine, x), params)
        return i + 1, add_block(acc, own, o, j, j < counts[o], mine)

    init = (jnp.zeros((), counts.dtype), init)
    return jax.lax.while_loop(lambda c: c[0] < ends[-1], body, init)[1]


# Selecting an option's parameters and adding to its gradient by a one-hot product
# rather than an index: under ``vmap`` (seeds) an index becomes a gather or a scatter,
# which XLA:CPU runs element by element; the products are dense and cheap (O is small).
def _pick(mine: jax.Array, stacked: jax.Array) -> jax.Array:
    """``stacked[o]`` for the one-hot ``mine`` [O]."""
    return jnp.tensordot(mine.astype(stacked.dtype), stacked, axes=1)


def _spread(mine: jax.Array, x: jax.Array) -> jax.Array:
    """``x`` at option o of a stacked ``[O, ...]`` zero, for the one-hot ``mine``."""
    return mine.astype(x.dtype).reshape((-1,) + (1,) * x.ndim) * x
