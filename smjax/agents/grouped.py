"""Gradients of every option's loss at once, at the cost of the rows each option has.

A learner per option (parameters stacked on a leading axis O) trains on its own rows of
a batch. Running every option's network over every row and masking the others' out
costs rows x options; here each option's rows are cut into blocks of ``block`` rows
(the last one padded), and a loop runs the blocks through their own option's
parameters, adding each block's gradient to that option's. The loop runs until the
blocks there are (a traced count) are done, so the work follows the rows there are
(plus at most one padded block per option), not a static worst case. Under ``vmap``
(seeds) the loop runs as often as the seed with the most blocks needs.
``grouped_sums`` is the same loop for values that need no gradient (a forward pass over
the rows), ``grouped_rows`` for a value per row.

A pass of the loop takes one block on a CPU and several at once on an accelerator
(``blocks_per_step``): a CPU pays for the work, an accelerator for each pass's kernel
launches (benchmarks/RESULTS.md, "The cost of a joint update").

Why blocks and not ``jax.lax.ragged_dot``: seed-vmapped, a ragged product over 5 groups
takes longer than the dense product of every row with every group's weights, on XLA:CPU
and on a GPU alike (benchmarks/grouped_layers.py).
"""
from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp


def blocks_per_step(requested: int, expected_rows: int, block: int, num_options: int) -> int:
    """Blocks per pass of the loop: ``requested``, or for 0 one on a CPU and, on an
    accelerator, as many as ``expected_rows`` (the rows a call usually has) fill with
    one partly filled block per option, so one pass usually does it all."""
    if requested:
        return requested
    if jax.default_backend() == "cpu":
        return 1
    return -(-expected_rows // block) + num_options


def block_count(counts: jax.Array, block: int) -> jax.Array:
    """int [O]: the blocks each option's ``counts`` rows fill."""
    return (counts + block - 1) // block


def grouped_grads(block_loss: Callable, params: Any, counts: jax.Array,
                  block: int, per_step: int = 1) -> tuple[Any, dict]:
    """Every option's gradient and summed auxiliary values over its own rows.

    ``params``: stacked per option (leading axis O); ``counts`` int [O]: option o's rows
    are its rows 0 .. counts[o] - 1. ``block_loss(option_params, o, rows, valid) ->
    (loss, aux)`` is option o's loss on ``rows`` (int [block]; ``valid``: bool [block],
    False past its count), a part of a sum over its blocks (padding rows must add
    nothing); ``aux`` is a dict of scalars. Returns the grads (stacked like ``params``)
    and the sum per option ([O]) of the loss (``"loss"``) and of each aux value.
    ``per_step`` blocks go through the loop at once (``_block_loop``)."""
    grad_fn = jax.value_and_grad(block_loss, has_aux=True)

    def one_block(own, o, j, valid):
        (loss, aux), g = grad_fn(own, o, j, valid)
        return g, dict(aux, loss=loss)

    def loss_and_aux(own, o, j, valid):
        loss, aux = block_loss(own, o, j, valid)
        return dict(aux, loss=loss)

    zeros = jax.tree.map(jnp.zeros_like, params)
    init = (zeros, _zero_sums(loss_and_aux, params, counts, block))
    return _block_loop(one_block, params, counts, block, init, per_step)


def grouped_sums(block_values: Callable, params: Any, counts: jax.Array, block: int,
                 per_step: int = 1) -> dict:
    """Every option's sums of ``block_values(option_params, o, rows, valid) -> dict of
    scalars`` over its own rows (as ``grouped_grads``, without a gradient): a pass that
    only reads the networks, at the price of a forward pass over the rows there are."""
    init = _zero_sums(block_values, params, counts, block)
    return _block_loop(block_values, params, counts, block, init, per_step)


def grouped_rows(block_values: Callable, params: Any, counts: jax.Array, block: int,
                 size: int, per_step: int = 1) -> jax.Array:
    """float [O, size]: ``block_values(option_params, o, rows, valid) -> [block]`` at each
    option's own positions ``rows`` (0 past its count): a per-row forward pass over the rows
    there are, as ``grouped_sums`` is a summed one."""
    def placed(own, o, j, valid):
        values = jnp.where(valid, block_values(own, o, j, valid), 0.0).astype(jnp.float32)
        return jax.lax.dynamic_update_slice(jnp.zeros((size + block,), jnp.float32), values,
                                            (j[0],))

    init = jnp.zeros((counts.shape[0], size + block), jnp.float32)
    return _block_loop(placed, params, counts, block, init, per_step)[:, :size]


def _zero_sums(block_values: Callable, params: Any, counts: jax.Array, block: int) -> dict:
    """A zero [O] for each scalar that ``block_values`` gives."""
    rows = jnp.arange(block, dtype=counts.dtype)
    own = jax.tree.map(lambda x: x[0], params)
    values = jax.eval_shape(block_values, own, jnp.int32(0), rows, rows < 0)
    return jax.tree.map(lambda x: jnp.zeros((counts.shape[0],), x.dtype), values)


def _block_loop(one_block: Callable, params: Any, counts: jax.Array, block: int, init,
                per_step: int):
    """The sum, into ``init`` at each block's option, of ``one_block(option_params, o,
    rows, valid)`` over every block of every option's rows, ``per_step`` blocks per pass
    of the loop. One at a time suits a CPU (no work past the last block); several at
    once (vmapped, one batched kernel per layer) suit an accelerator, where a pass's
    launches cost more than the at most ``per_step - 1`` empty blocks of the last one."""
    num_options = counts.shape[0]
    blocks = block_count(counts, block)
    ends = jnp.cumsum(blocks)
    rows = jnp.arange(block, dtype=counts.dtype)

    def one(i):
        """Block i through its option's parameters, and (one-hot) where its sums go."""
        o = jnp.sum(ends <= i).astype(jnp.int32)  # the option whose blocks cover block i
        if per_step > 1:  # a pass's blocks past the last one: the last option's, adding nothing
            o = jnp.minimum(o, num_options - 1)
        j = (i - (ends[o] - blocks[o])) * block + rows
        hot = jnp.arange(num_options) == o
        valid, mine = j < counts[o], hot
        if per_step > 1:
            inside = i < ends[-1]
            valid, mine = valid & inside, hot & inside
        own = jax.tree.map(lambda x: _pick(hot, x), params)
        return one_block(own, o, j, valid), mine

    def body(carry):
        i, acc = carry
        if per_step == 1:
            new, mine = one(i)
            acc = jax.tree.map(lambda a, x: a + _spread(mine, x), acc, new)
        else:
            new, mine = jax.vmap(one)(i + jnp.arange(per_step, dtype=i.dtype))
            acc = jax.tree.map(lambda a, x: a + _spread_many(mine, x), acc, new)
        return i + per_step, acc

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


def _spread_many(mine: jax.Array, x: jax.Array) -> jax.Array:
    """The sum of ``_spread(mine[k], x[k])`` over k (``mine`` [K, O], ``x`` [K, ...])."""
    return jnp.tensordot(mine.astype(x.dtype), x, axes=([0], [0]))
