"""Craft's state, traced params and static config."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np
from flax import struct

from smjax.core.overrides import INT32_MAX, parse_int
from smjax.envs.craft import constants as C

OBSERVATIONS = ("paper", "compact", "none")


@struct.dataclass
class CraftState:
    """One Craft world.

    grid: uint8 [12, 12] kind ids indexed ``grid[x, y]`` (the agent is not on the grid).
    pos: int32 [2] agent (x, y). direction: int32, facing (0 DOWN, 1 UP, 2 LEFT, 3 RIGHT).
    inventory: int32 [31] counts per kind id (only item slots 7..30 are ever non-zero).
    step: int32, steps taken in this episode.
    """

    grid: jax.Array
    pos: jax.Array
    direction: jax.Array
    inventory: jax.Array
    step: jax.Array


@struct.dataclass
class CraftParams:
    """Traced parameters (can be vmapped for sweeps).

    max_steps: step cap (truncation). goal: kind id of the goal item.
    use_fixed_map: if True every reset restores ``fixed_grid``/``fixed_pos``/``fixed_direction``
    (the reference's one-map quirk, and maps loaded from ASCII); else a fresh map is drawn.
    """

    max_steps: jax.Array
    goal: jax.Array
    use_fixed_map: jax.Array
    fixed_grid: jax.Array
    fixed_pos: jax.Array
    fixed_direction: jax.Array


@dataclass(frozen=True)
class CraftConfig:
    """Static configuration: everything that decides shapes or which code is compiled."""

    task: str = "get_gem"
    observation: str = "paper"
    side_cost: str = "held"

    def __post_init__(self):
        C.check_task(self.task)
        if self.observation not in OBSERVATIONS:
            raise ValueError(
                f"observation must be one of {OBSERVATIONS}, got {self.observation!r}"
            )

    @property
    def goal(self) -> str:
        return C.TASKS[self.task]

    @property
    def world(self) -> str:
        return C.world_kind(self.task)


def make_params(
    task: str,
    max_steps: int | None = None,
    fixed_state: CraftState | None = None,
) -> CraftParams:
    """Params for a task; ``fixed_state`` (one unbatched state) turns on the fixed map."""
    goal = C.TASKS[C.check_task(task)]
    # strict: 0, -1 or 1.5 would truncate every step; 2**31 would overflow int32
    cap = C.STEP_CAP[goal] if max_steps is None else parse_int("max_steps", max_steps, 1, INT32_MAX)
    # numpy, not jax.numpy: making a task runs no XLA program, so every refusal that
    # follows (a config, a hierarchy, the memory estimate) comes before any compile; the
    # arrays become device arrays where a program takes them
    if fixed_state is None:
        grid = np.zeros((C.GRID_SIZE, C.GRID_SIZE), np.uint8)
        pos, direction = np.zeros(2, np.int32), C.DOWN
    else:
        grid, pos, direction = fixed_state.grid, fixed_state.pos, fixed_state.direction
    return CraftParams(
        max_steps=np.asarray(cap, np.int32),
        goal=np.asarray(C.KIND_ID[goal], np.int32),
        use_fixed_map=np.asarray(fixed_state is not None),
        fixed_grid=np.asarray(grid, np.uint8),
        fixed_pos=np.asarray(pos, np.int32),
        fixed_direction=np.asarray(direction, np.int32),
    )
