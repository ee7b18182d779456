"""State, params and static config of Fetch & Stack, plus pure accessors.

Accessors read positions straight from ``qpos``/``qvel`` rather than from ``xpos``:
after ``mjx.step`` the kinematic fields describe the configuration *before* the last
integration, while ``qpos`` is the current one. The grip point is the gripper body's
origin (its free joint's position), and a block's free-joint position is its centre.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from mujoco import mjx

from smjax.envs.fetch.model import PhysicsConfig, check_num_blocks


@struct.dataclass
class FetchState:
    """One environment's state (vmap for batches).

    Attributes:
      data: the MJX physics state.
      goals: float32[N, 3], goal position of every block (a tower: goal_i = goal_0 + i*0.05 z).
      step: int32, env steps taken in this episode.
      placed: bool[N], block i within ``success_distance`` of goal i after the last step.
    """

    data: mjx.Data
    goals: jax.Array
    step: jax.Array
    placed: jax.Array


@struct.dataclass
class FetchParams:
    """Traced parameters (vmappable for sweeps); shapes never depend on them. numpy by
    default: making the task runs no XLA program (every refusal comes before a compile)."""

    max_steps: jax.Array = struct.field(default_factory=lambda: np.asarray(150, np.int32))
    action_scale: jax.Array = struct.field(default_factory=lambda: np.asarray(0.05, np.float32))
    success_distance: jax.Array = struct.field(
        default_factory=lambda: np.asarray(0.04, np.float32))
    clear_distance: jax.Array = struct.field(default_factory=lambda: np.asarray(0.08, np.float32))
    spawn_range: jax.Array = struct.field(default_factory=lambda: np.asarray(0.15, np.float32))
    min_gripper_distance: jax.Array = struct.field(
        default_factory=lambda: np.asarray(0.1, np.float32))
    min_block_distance: jax.Array = struct.field(
        default_factory=lambda: np.asarray(0.055, np.float32))


@dataclass(frozen=True)
class FetchConfig:
    """Static configuration: anything that changes shapes or the compiled program.

    Attributes:
      num_blocks: N, 1..6 (the paper uses 3 and 4).
      physics: timestep / substeps / solver settings.
      obs_include_goals: append the N goals (3N floats) to the 10 + 15N observation.
        Off by default to match the reference's observation; a learner that must find
        the tower's place from observations alone needs it on.
      spawn_candidates: candidates drawn per block by the vectorised rejection sampler.
    """

    num_blocks: int = 3
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    obs_include_goals: bool = False
    spawn_candidates: int = 64

    def __post_init__(self):
        check_num_blocks(self.num_blocks)
        if self.spawn_candidates < 1:
            raise ValueError(f"spawn_candidates must be >= 1, got {self.spawn_candidates}")

    @property
    def obs_size(self) -> int:
        return 10 + 15 * self.num_blocks + (3 * self.num_blocks if self.obs_include_goals else 0)


# ---- accessors (the qpos layout is fixed by model.scene_xml; see model.model_index) ----
# gripper free joint: qpos[0:7], qvel[0:6]; fingers: qpos[7:9], qvel[6:8];
# block i: qpos[9 + 7i : 16 + 7i], qvel[8 + 6i : 14 + 6i].
GRIPPER_QPOS, GRIPPER_QVEL = 0, 0
FINGER_QPOS, FINGER_QVEL = 7, 6
BLOCK_QPOS0, BLOCK_QVEL0 = 9, 8


def gripper_pos(state: FetchState) -> jax.Array:
    """float32[3], the grip point (between the fingertips)."""
    return state.data.qpos[GRIPPER_QPOS:GRIPPER_QPOS + 3]


def gripper_vel(state: FetchState) -> jax.Array:
    return state.data.qvel[GRIPPER_QVEL:GRIPPER_QVEL + 3]


def finger_qpos(state: FetchState) -> jax.Array:
    """float32[2], each finger's opening (0 closed .. 0.05 open)."""
    return state.data.qpos[FINGER_QPOS:FINGER_QPOS + 2]


def finger_qvel(state: FetchState) -> jax.Array:
    return state.data.qvel[FINGER_QVEL:FINGER_QVEL + 2]


def _block_rows(vec: jax.Array, start: int, stride: int, width: int, n: int) -> jax.Array:
    rows = vec[start:start + stride * n].reshape(n, stride)
    return rows[:, :width]


def num_blocks_of(state: FetchState) -> int:
    return state.goals.shape[-2]


def block_pos(state: FetchState) -> jax.Array:
    """float32[N, 3], block centres."""
    return _block_rows(state.data.qpos, BLOCK_QPOS0, 7, 3, num_blocks_of(state))


def block_quat(state: FetchState) -> jax.Array:
    """float32[N, 4], block orientations (w, x, y, z)."""
    n = num_blocks_of(state)
    return state.data.qpos[BLOCK_QPOS0:BLOCK_QPOS0 + 7 * n].reshape(n, 7)[:, 3:]


def block_linvel(state: FetchState) -> jax.Array:
    return _block_rows(state.data.qvel, BLOCK_QVEL0, 6, 3, num_blocks_of(state))


def block_angvel_local(state: FetchState) -> jax.Array:
    """float32[N, 3], angular velocity in each block's own frame (MuJoCo free-joint convention)."""
    n = num_blocks_of(state)
    return state.data.qvel[BLOCK_QVEL0:BLOCK_QVEL0 + 6 * n].reshape(n, 6)[:, 3:]


def quat_to_mat(quat: jax.Array) -> jax.Array:
    """Rotation matrices [..., 3, 3] of unit quaternions [..., 4] (w, x, y, z)."""
    q = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def quat_to_euler(quat: jax.Array) -> jax.Array:
    """Euler angles [..., 3] (roll x, pitch y, yaw z; R = Rz Ry Rx) of quaternions (w, x, y, z)."""
    q = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = jnp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jnp.arcsin(jnp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = jnp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return jnp.stack([roll, pitch, yaw], axis=-1)
