"""Spread seeds (and environments within a seed) over all visible devices.

A 2-D ``Mesh`` with axes ``("seed", "env")``: seeds are split over as many devices as
divide their number, and the remaining factor splits each seed's environments. Every
array of the training state has the seed axis first; the environment carry has the
environment axis second. XLA partitions the compiled chunk from these input shardings
(GSPMD), so the same code runs on one CPU, one GPU, several GPUs or several processes.
With seed-only sharding each seed's computation stays on one device and the numbers are
bitwise those of a single-device run; splitting environments changes the order of some
float reductions (results then agree up to float tolerance).
"""
from __future__ import annotations

import math

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P


def training_mesh(num_seeds: int, num_envs: int, devices=None) -> Mesh | None:
    """The mesh for a run, or None when one device is all there is (or all that divides)."""
    devices = list(devices if devices is not None else jax.devices())
    n = len(devices)
    if n <= 1:
        return None
    seed_ways = math.gcd(num_seeds, n)
    env_ways = n // seed_ways
    while env_ways > 1 and num_envs % env_ways:
        env_ways -= 1
    used = seed_ways * env_ways
    if used <= 1:
        return None
    return Mesh(np.array(devices[:used]).reshape(seed_ways, env_ways), ("seed", "env"))


def seed_sharding(mesh: Mesh, tree, env_axis: bool = False):
    """NamedShardings for a pytree whose leaves lead with the seed axis (and env axis)."""
    def spec(x):
        if env_axis and x.ndim >= 2:
            return NamedSharding(mesh, P("seed", "env"))
        return NamedSharding(mesh, P("seed") if x.ndim >= 1 else P())
    return jax.tree.map(spec, tree)


def state_shardings(mesh: Mesh, state):
    """Shardings for a ``SeedState``: the environment carry is split over both axes."""
    return type(state)(
        carry=seed_sharding(mesh, state.carry, env_axis=True),
        learner=seed_sharding(mesh, state.learner),
        key=seed_sharding(mesh, state.key),
    )
