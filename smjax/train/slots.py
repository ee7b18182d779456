"""The run's slots and their device state.

A slot is one seed of one sweep point (without a sweep: one seed). ``Slots`` holds, per
slot, its seed, its config (its sweep point's) and swept hyper-parameters, and the device
state of all slots (``TrainArrays``) placed on the training mesh; the stages and the driver
loop change that state through it.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.train import distributed as dist
from smjax.train.seed_arrays import local
from smjax.train.config import TrainConfig
from smjax.train.sharding import seed_sharding, state_shardings
from smjax.train.state import TrainArrays


class Slots:
    """Per slot: ``seeds``, ``configs`` (the config its run alone would have: its sweep
    point's) and ``hp`` (learner hyper-parameter leaves that differ from the config);
    ``arrays``: every slot's device state on ``mesh`` (None: one device)."""

    def __init__(self, seeds: list[int], configs: list[TrainConfig], hp: dict, mesh):
        self.seeds, self.configs, self.hp, self.mesh = list(seeds), list(configs), hp, mesh
        self.arrays: TrainArrays | None = None

    def __len__(self) -> int:
        return len(self.seeds)

    def level_gamma(self, name: str | None, s: int) -> float:
        """The discount slot ``s`` trains level ``name`` with (None: an option no level
        trains): its ``LevelSettings.gamma``, the one source of a discount (a level's own,
        else the config's; a swept gamma is its point's config's, and a sweep refuses
        gamma where a level sets its own)."""
        return self.configs[s].for_level(name).gamma

    def init_learner(self, engine, keys: jax.Array):
        """Fresh learners per slot, with each slot's swept hyper-parameters."""
        learner = engine.init_learner(keys)
        if self.hp:
            learner = learner.replace(hp={**learner.hp, **self.hp})
        return learner

    def set(self, arrays: TrainArrays) -> None:
        """New device state, put on the mesh (seed axis, then environment axis), or
        committed to the one device."""
        if self.mesh is not None:
            shardings = seed_sharding(self.mesh, arrays).replace(
                state=state_shardings(self.mesh, arrays.state))
            self.arrays = dist.place(arrays, shardings)
        else:
            self.arrays = self.committed(arrays)

    def committed(self, tree):
        """``tree`` committed to the one device the state lives on. A compiled chunk
        returns committed arrays, and jit compiles a program again for committed arguments
        where it first saw uncommitted ones: the run's keys start committed, so every small
        program (resets, inits, seed selections) compiles once. With a mesh, host-side
        changes work on local copies (``local``) and ``set`` places the result: unchanged."""
        if self.mesh is not None:
            return tree
        # most leaves come out of a program on committed inputs, committed already (and
        # a device_put costs a dispatch per leaf)
        device = jax.devices()[0]
        return jax.tree.map(
            lambda x: x if isinstance(x, jax.Array) and x.committed and x.devices() == {device}
            else jax.device_put(x, device), tree)

    def local(self) -> TrainArrays:
        """The device state as arrays this process holds whole (for host-side changes)."""
        return self.arrays if self.mesh is None else jax.tree.map(local, self.arrays)

    def small(self, tree):
        """Small per-call inputs (flags, masks) on the mesh: with several processes every
        input of a compiled program must be a global array."""
        if self.mesh is None:
            return tree
        return dist.place(tree, seed_sharding(self.mesh, tree))

    def per_seed(self, values, dtype) -> jax.Array:
        return self.small(jnp.asarray(values, dtype))

    def mask(self, seeds: list[int]) -> np.ndarray:
        return np.asarray([s in seeds for s in range(len(self.seeds))])
