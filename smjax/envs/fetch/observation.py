"""Observation (10 + 15N floats).

Layout, the reference's (docs/environments.md, Fetch); velocities are
displacements per env step, i.e. velocity x control dt, as in the reference:

  [0:3]  grip point position          [3:5]  finger openings (qpos)
  [5:8]  grip point velocity * dt      [8:10] finger velocities * dt
  then per block i (15 floats at 10 + 15 i):
  pos 3, pos - grip 3, euler (roll, pitch, yaw) 3, (block - grip) linear velocity * dt 3,
  world angular velocity * dt 3.
  Optionally (``FetchConfig.obs_include_goals``) the N goals, 3N floats, at the end.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.fetch import types as st
from smjax.envs.fetch.types import FetchConfig, FetchState


def observation(state: FetchState, config: FetchConfig) -> jax.Array:
    """float32[obs_size]; non-finite values (a diverged simulation) read as 0."""
    return jnp.nan_to_num(raw_observation(state, config), posinf=0.0, neginf=0.0)


def raw_observation(state: FetchState, config: FetchConfig) -> jax.Array:
    dt = config.physics.control_dt
    grip = st.gripper_pos(state)
    grip_vel = st.gripper_vel(state) * dt
    blocks = st.block_pos(state)
    quats = st.block_quat(state)
    rot = st.quat_to_mat(quats)
    angvel_world = jnp.einsum("nij,nj->ni", rot, st.block_angvel_local(state)) * dt
    per_block = jnp.concatenate(
        [
            blocks,
            blocks - grip,
            st.quat_to_euler(quats),
            st.block_linvel(state) * dt - grip_vel,
            angvel_world,
        ],
        axis=-1,
    )
    parts = [grip, st.finger_qpos(state), grip_vel, st.finger_qvel(state) * dt, per_block.ravel()]
    if config.obs_include_goals:
        parts.append(state.goals.ravel())
    return jnp.concatenate(parts).astype(jnp.float32)
