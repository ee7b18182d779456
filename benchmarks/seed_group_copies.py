"""What a call of a program in CPU seed groups spends copying rows, with and without the
groups' arrays kept from the last call (``smjax.train.seed_threads``).

A program over ``--seeds`` seeds, in groups on threads as the trainer runs it, takes a
donated state of ``--state-mb`` MB (a chunk's learners and environments) and a read-only
bank of ``--bank-mb`` MB, and returns the state, a little changed; the calls chain, each on
the state the last one joined, with the seeds dealt the same way. ``copy`` disables the
kept arrays (every call copies every group's rows out, as before they were kept). The two
alternate ``--repeats`` times; medians of the milliseconds a call.

    JAX_PLATFORMS=cpu python benchmarks/seed_group_copies.py --seeds 10 --state-mb 24
"""
from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp

from smjax.train.seed_threads import SeedGroups


def per_call_ms(keep: bool, seeds: int, state_mb: float, bank_mb: float, calls: int) -> float:
    state = jnp.ones((seeds, int(state_mb * 2**18 / seeds)), jnp.float32)
    bank = jnp.ones((seeds, int(bank_mb * 2**18 / seeds)), jnp.float32)
    groups = SeedGroups.for_program(2, (state, bank))
    if not keep:
        groups._reuse = lambda whole, key: None  # noqa: SLF001 - the path without kept arrays
    step = jax.jit(lambda s, b: (s * 1.0001 + b[:, :1] * 1e-9, s.sum(1)), donate_argnums=(0,))
    program = groups.program(step.lower(*groups.shapes((state, bank))).compile())
    for _ in range(3):
        state, _ = program(state, bank)
    t0 = time.perf_counter()
    for _ in range(calls):
        state, _ = program(state, bank)
    jax.block_until_ready(state)
    return (time.perf_counter() - t0) / calls * 1000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--state-mb", type=float, default=24.0)
    ap.add_argument("--bank-mb", type=float, default=6.0)
    ap.add_argument("--calls", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    times = {"kept": [], "copy": []}
    for _ in range(a.repeats):
        for way in times:
            times[way].append(per_call_ms(way == "kept", a.seeds, a.state_mb, a.bank_mb, a.calls))
    for way, ms in times.items():
        print(f"{way}: {statistics.median(ms):.1f} ms a call (runs {', '.join(f'{m:.1f}' for m in ms)})")


if __name__ == "__main__":
    main()
