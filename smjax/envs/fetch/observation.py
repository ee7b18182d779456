"""Observation (10 + 15N floats) and the incremental stacking reward.

Observation layout, the reference's (docs/environments.md, Fetch); velocities are
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

from smjax.envs.fetch import state as st
from smjax.envs.fetch.state import FetchConfig, FetchParams, FetchState


def observation(state: FetchState, config: FetchConfig) -> jax.Array:
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


def blocks_placed(state: FetchState, params: FetchParams) -> jax.Array:
    """bool[N]: block i within ``success_distance`` of goal i."""
    dist = jnp.linalg.norm(st.block_pos(state) - state.goals, axis=-1)
    return dist < params.success_distance


def gripper_clear(state: FetchState, params: FetchParams) -> jax.Array:
    """True when the grip point is farther than ``clear_distance`` from every goal."""
    dist = jnp.linalg.norm(state.goals - st.gripper_pos(state), axis=-1)
    return jnp.all(dist > params.clear_distance)


def reward(state: FetchState, params: FetchParams) -> jax.Array:
    """-(blocks not placed); when all are placed, +1 if the gripper is clear of every goal."""
    placed = blocks_placed(state, params)
    missing = jnp.sum(~placed).astype(jnp.float32)
    bonus = jnp.where(jnp.all(placed) & gripper_clear(state, params), 1.0, 0.0)
    return -missing + bonus


def score(reward_value: jax.Array, num_blocks: int) -> jax.Array:
    """The reported score (min(0, r) + N) / N: the fraction of blocks in place."""
    return (jnp.minimum(0.0, reward_value) + num_blocks) / num_blocks
