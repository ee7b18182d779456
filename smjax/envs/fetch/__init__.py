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

import contextlib
import io

# MuJoCo prints on import that its optional warp backend is missing ("Failed to import
# warp"); smjax uses MJX's JAX backend, so the note is noise in every command's output
with contextlib.redirect_stdout(io.StringIO()):
    try:
        from mujoco import mjx  # noqa: F401
    except ModuleNotFoundError as err:  # an optional dependency (the ``fetch`` extra)
        raise ModuleNotFoundError(
            f"Fetch & Stack needs MuJoCo MJX ({err}): pip install 'smjax[fetch]' "
            f"(in a clone: pip install -e '.[fetch]')", name=err.name) from err

from smjax.envs.fetch.env import FetchEnv, make_fetch, register_all
from smjax.envs.fetch.model import PhysicsConfig
from smjax.envs.fetch.types import FetchConfig, FetchParams, FetchState

__all__ = ["FetchEnv", "FetchConfig", "FetchParams", "FetchState", "PhysicsConfig", "make_fetch"]

register_all()
