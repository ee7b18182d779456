"""Render one (unbatched) Fetch state with MuJoCo's offscreen renderer.

The MJX state is copied into a CPU ``MjData`` (qpos, qvel, mocap, goal sites), then drawn
by ``mujoco.Renderer``. Headless machines need an OpenGL backend chosen *before* mujoco is
imported: ``MUJOCO_GL=egl`` (hardware/driver EGL; Debian/Ubuntu package ``libegl1``) or
``MUJOCO_GL=osmesa`` (software; package ``libosmesa6``).
"""
from __future__ import annotations

import os

import mujoco
import numpy as np

from smjax.envs.fetch.model import build_model

_CAMERA = dict(lookat=(1.32, 0.75, 0.45), distance=1.0, azimuth=150.0, elevation=-30.0)


def _gl_hint(err: Exception) -> RuntimeError:
    current = os.environ.get("MUJOCO_GL", "(unset)")
    return RuntimeError(
        f"MuJoCo could not create an OpenGL context for offscreen rendering "
        f"(MUJOCO_GL={current}): {type(err).__name__}: {err}. Set MUJOCO_GL=egl "
        f"(needs libegl1 and a GPU driver) or MUJOCO_GL=osmesa (software, needs libosmesa6) "
        f"before Python imports mujoco."
    )


class FrameRenderer:
    """Keeps one ``mujoco.Renderer`` per environment (creating a GL context is slow)."""

    def __init__(self, env, width: int = 480, height: int = 360):
        # A private CPU model: goal sites are moved per frame without touching env's model.
        self.model = build_model(env.num_blocks, env.config.physics)
        self.data = mujoco.MjData(self.model)
        self.goal_sites = env.index.goal_site
        try:
            self.renderer = mujoco.Renderer(self.model, height=height, width=width)
        except Exception as err:  # mujoco raises several types depending on the backend
            raise _gl_hint(err) from err
        self.camera = mujoco.MjvCamera()
        self.camera.lookat[:] = _CAMERA["lookat"]
        self.camera.distance = _CAMERA["distance"]
        self.camera.azimuth = _CAMERA["azimuth"]
        self.camera.elevation = _CAMERA["elevation"]

    def __call__(self, state) -> np.ndarray:
        data = state.data
        if np.ndim(data.qpos) != 1:
            raise ValueError(
                f"render takes one unbatched state; got qpos of shape {np.shape(data.qpos)} "
                f"(index the batch first, e.g. jax.tree.map(lambda x: x[0], state))")
        self.data.qpos[:] = np.asarray(data.qpos)
        self.data.qvel[:] = np.asarray(data.qvel)
        self.data.mocap_pos[:] = np.asarray(data.mocap_pos)
        self.data.mocap_quat[:] = np.asarray(data.mocap_quat)
        for site, goal in zip(self.goal_sites, np.asarray(state.goals)):
            self.model.site_pos[site] = goal
        mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        return np.asarray(self.renderer.render(), dtype=np.uint8)


_CACHE: dict[tuple[int, int, int], FrameRenderer] = {}


def render_state(env, state, width: int = 480, height: int = 360) -> np.ndarray:
    """RGB uint8 (height, width, 3) image of one state."""
    key = (id(env), width, height)
    if key not in _CACHE:
        _CACHE[key] = FrameRenderer(env, width=width, height=height)
    return _CACHE[key](state)
