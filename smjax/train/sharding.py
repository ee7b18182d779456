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
    processes = sorted({d.process_index for d in devices})
    if len(processes) > 1:
        return _multiprocess_mesh(num_seeds, num_envs, devices, processes)
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


def _multiprocess_mesh(num_seeds: int, num_envs: int, devices: list, processes: list) -> Mesh:
    """Over several processes every process must own an equal part of the mesh (a process
    without devices in it could not take part in the compiled chunk), so the split is
    chosen among those that use the same number of devices on every process."""
    local = {p: [d for d in devices if d.process_index == p] for p in processes}
    per_process = min(len(v) for v in local.values())
    P_, n = len(processes), per_process * len(processes)
    seed_ways = math.gcd(num_seeds, n)
    while seed_ways >= 1:
        env_ways = n // seed_ways
        while env_ways >= 1:
            used = seed_ways * env_ways
            if num_envs % env_ways == 0 and used % P_ == 0 and n % used == 0:
                take = used // P_
                # process-major order: with seeds outermost, a seed's environments stay
                # on one process when they fit (no cross-host traffic inside a seed)
                chosen = [d for p in processes for d in local[p][:take]]
                return Mesh(np.array(chosen).reshape(seed_ways, env_ways), ("seed", "env"))
            env_ways -= 1
        seed_ways -= 1
        while seed_ways > 1 and num_seeds % seed_ways:
            seed_ways -= 1
    raise ValueError(
        f"cannot spread {num_seeds} seeds x {num_envs} environments over {P_} processes with "
        f"{per_process} devices each: use a number of seeds or num_envs divisible by {P_}")


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
