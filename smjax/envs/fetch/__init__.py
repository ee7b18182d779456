"""Fetch & Stack in MuJoCo MJX: stack N blocks into a tower with a floating gripper.

Tasks: ``fetch/stack1`` .. ``fetch/stack6`` (``stack3`` and ``stack4`` are the paper's).
The number of blocks N comes from the task name, or from the ``num_blocks`` override,
which wins: ``smjax.make("fetch/stack3", num_blocks=5)`` is the 5-block task.

Overrides (keyword-only): ``num_blocks`` (1..6), ``substeps`` and ``timestep`` (physics
step; default 8 x 0.005 s = 0.04 s per env step), ``solver_iterations``,
``ls_iterations``, ``obs_include_goals`` (append the 3N goal coordinates to the
observation), ``max_steps`` (default 50 N).

Rendering uses MuJoCo's offscreen renderer: set ``MUJOCO_GL=egl`` (GPU/headless EGL) or
``MUJOCO_GL=osmesa`` (software) before importing mujoco on a machine without a display.
"""
from __future__ import annotations

import jax.numpy as jnp

from smjax.core.overrides import INT32_MAX, parse_bool, parse_float, parse_int
from smjax.core.registry import register
from smjax.envs.fetch.env import FetchEnv
from smjax.envs.fetch.model import MAX_BLOCKS, MIN_BLOCKS, PhysicsConfig, check_num_blocks
from smjax.envs.fetch.state import FetchConfig, FetchParams, FetchState

__all__ = ["FetchEnv", "FetchConfig", "FetchParams", "FetchState", "PhysicsConfig", "make_fetch"]


def make_fetch(
    default_blocks: int,
    *,
    num_blocks: int | None = None,
    substeps: int = PhysicsConfig.substeps,
    timestep: float = PhysicsConfig.timestep,
    solver_iterations: int = PhysicsConfig.solver_iterations,
    ls_iterations: int = PhysicsConfig.ls_iterations,
    obs_include_goals: bool = False,
    max_steps: int | None = None,
) -> tuple[FetchEnv, FetchParams]:
    """Build (env, params) for N = ``num_blocks`` (or ``default_blocks``) blocks."""
    n = check_num_blocks(default_blocks if num_blocks is None else
                         parse_int("num_blocks", num_blocks, MIN_BLOCKS, MAX_BLOCKS))
    # strict: a truncated 2.7 substeps or a NaN timestep would silently change the physics
    physics = PhysicsConfig(timestep=parse_float("timestep", timestep, 0.0, 0.1, low_open=True),
                            substeps=parse_int("substeps", substeps, 1, 1000),
                            solver_iterations=parse_int("solver_iterations", solver_iterations, 1, 1000),
                            ls_iterations=parse_int("ls_iterations", ls_iterations, 1, 1000))
    env = FetchEnv(FetchConfig(num_blocks=n, physics=physics,
                               obs_include_goals=parse_bool("obs_include_goals", obs_include_goals)))
    params = env.default_params
    if max_steps is not None:
        steps = parse_int("max_steps", max_steps, 1, INT32_MAX)
        params = params.replace(max_steps=jnp.asarray(steps, jnp.int32))
    return env, params


def _factory(default_blocks: int):
    def factory(*, num_blocks: int | None = None, substeps: int = PhysicsConfig.substeps,
                timestep: float = PhysicsConfig.timestep,
                solver_iterations: int = PhysicsConfig.solver_iterations,
                ls_iterations: int = PhysicsConfig.ls_iterations,
                obs_include_goals: bool = False, max_steps: int | None = None):
        return make_fetch(default_blocks, num_blocks=num_blocks, substeps=substeps,
                          timestep=timestep, solver_iterations=solver_iterations,
                          ls_iterations=ls_iterations, obs_include_goals=obs_include_goals,
                          max_steps=max_steps)

    return factory


for _n in range(MIN_BLOCKS, MAX_BLOCKS + 1):
    _paper = " (paper)" if _n in (3, 4) else ""
    register(f"fetch/stack{_n}", _factory(_n),
             f"MJX gripper stacks {_n} block(s) into a tower{_paper}; num_blocks overrides N")
