"""Ways to run two dense layers per option over rows sorted by option: forward and gradient.

Joint fine-tuning's update runs every option's network on its own rows of a minibatch
(``smjax.agents.grouped``). This times, seed-vmapped on one minibatch (``--rows`` rows in
``--options`` runs by option), the gradient of a two-layer tanh network's summed output
with respect to every option's weights, five ways:

* ``single``: one learner over every row (the floor: what one option alone would cost);
* ``ragged``: ``jax.lax.ragged_dot`` per layer, the rows grouped by option;
* ``blocks``: the rows cut into blocks of ``--block`` (one option's each, the last of each
  option padded), all at once, each block with its option's weights picked by a one-hot
  product (as ``smjax.agents.grouped`` picks them);
* ``take``: the same blocks, the weights picked by index;
* ``masked``: every option over every row, the others' rows masked out.

The gradients of ``ragged``, ``take`` and ``masked`` are checked against ``blocks``'s.

    python benchmarks/grouped_layers.py --seeds 10 --inputs 1586   # get_gem's paper observation
    python benchmarks/grouped_layers.py --seeds 2 --inputs 180     # its compact observation
"""
from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--inputs", type=int, default=1586, help="the first layer's inputs")
    ap.add_argument("--hidden", type=int, default=64)
    ap.add_argument("--rows", type=int, default=1024, help="a minibatch's rows")
    ap.add_argument("--block", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args(argv)
    S, K, N, R, B = args.seeds, args.inputs, args.hidden, args.rows, args.block
    counts = jnp.asarray([300, 250, 200, 150, 124], jnp.int32)  # rows per option
    counts = jnp.tile(counts * R // int(counts.sum()), (S, 1))
    O = counts.shape[1]
    key = jax.random.PRNGKey(0)
    x = jax.random.normal(key, (S, R, K))
    w1 = jax.random.normal(key, (S, O, K, N)) * 0.02
    w2 = jax.random.normal(key, (S, O, N, N)) * 0.1
    blocks_of = block_layout(R, O, B)

    def single(w1, w2, x, c):
        return jax.grad(lambda p: jnp.sum(jnp.tanh(jnp.tanh(x @ p[0]) @ p[1])))((w1[0], w2[0]))

    def ragged(w1, w2, x, c):
        def loss(p):
            h = jnp.tanh(jax.lax.ragged_dot(x, p[0], c))
            return jnp.sum(jnp.tanh(jax.lax.ragged_dot(h, p[1], c)))
        return jax.grad(loss)((w1, w2))

    def blocked(pick):
        def run(w1, w2, x, c):
            o, rows, valid = blocks_of(c)

            def loss(p):
                a, b = pick(p[0], o), pick(p[1], o)
                h = jnp.tanh(jnp.einsum("pbk,pkn->pbn", x[rows], a))
                return jnp.sum(jnp.tanh(jnp.einsum("pbn,pnm->pbm", h, b)) * valid[..., None])
            return jax.grad(loss)((w1, w2))
        return run

    def one_hot(w, o):
        return jnp.einsum("po,o...->p...", (o[:, None] == jnp.arange(O)).astype(w.dtype), w)

    def masked(w1, w2, x, c):
        owner = jnp.searchsorted(jnp.cumsum(c), jnp.arange(R), side="right")

        def loss(p):
            h = jnp.tanh(jnp.einsum("rk,okn->orn", x, p[0]))
            y = jnp.tanh(jnp.einsum("orn,onm->orm", h, p[1]))
            return jnp.sum(y * (owner[None, :, None] == jnp.arange(O)[:, None, None]))
        return jax.grad(loss)((w1, w2))

    ways = {"single": single, "ragged": ragged, "blocks": blocked(one_hot),
            "take": blocked(lambda w, o: w[o]), "masked": masked}
    grads = {}
    for name, fn in ways.items():
        program = jax.jit(jax.vmap(fn))
        grads[name] = jax.block_until_ready(program(w1, w2, x, counts))
        runs = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(program(w1, w2, x, counts))
            runs.append(time.perf_counter() - t0)
        print(f"{name:8s} {statistics.median(runs) * 1e3:8.3f} ms", flush=True)
    for name in ("ragged", "take", "masked"):
        err = max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(grads[name], grads["blocks"]))
        print(f"{name} against blocks: largest gradient difference {err:.2e}")
    print(f"seeds {S}, {R} rows of {K} inputs, {O} options, hidden {N}, blocks of {B}, on "
          f"{jax.devices()[0].device_kind}")


def block_layout(rows: int, options: int, block: int):
    """``counts [O] -> (option [P], row [P, block], valid [P, block])``: every option's rows
    (consecutive, in option order) in blocks of ``block``, P = rows / block + O of them (the
    most a minibatch needs: one partly filled block per option)."""
    def layout(counts):
        blocks = (counts + block - 1) // block
        ends, starts = jnp.cumsum(blocks), jnp.cumsum(counts) - counts
        i = jnp.arange(rows // block + options)
        o = jnp.minimum(jnp.sum(ends[None, :] <= i[:, None], 1), options - 1)
        j = (i - (ends[o] - blocks[o]))[:, None] * block + jnp.arange(block)[None, :]
        valid = (j < counts[o][:, None]) & (i < ends[-1])[:, None]
        return o, jnp.clip(starts[o][:, None] + j, 0, rows - 1), valid
    return layout


if __name__ == "__main__":
    main()
