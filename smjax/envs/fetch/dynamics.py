"""Fetch & Stack's transition and reward: one env step of physics, the incremental
stacking reward, the reported score, truncation and the divergence guard.

Action: float32[4] in [-1, 1] (clipped). ``a[:3]`` moves the mocap target of the grip
point by ``params.action_scale`` (0.05 m) per step per unit, clamped to the workspace box;
the target moves along a straight line over the substeps, so the gripper is dragged
smoothly instead of jumping 5 cm in one physics step. ``a[3]`` moves both finger position
targets by 0.05 m per unit (+1 opens fully, -1 closes fully in one step, 0 keeps the
current target, so doing nothing keeps a grasp; the reference instead re-targets the
current finger position, which loosens the grip when the action is 0).

Reward: -(number of blocks farther than ``success_distance`` (0.04 m) from their goal);
when all are placed, +1 if the grip point is farther than ``clear_distance`` (0.08 m)
from every goal, else 0. Score: (min(0, r) + N) / N, the fraction of blocks in place.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from mujoco import mjx

from smjax.envs.fetch import model as fm
from smjax.envs.fetch import types as st
from smjax.envs.fetch.types import FetchConfig, FetchParams, FetchState


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


def step(state: FetchState, action: jax.Array, params: FetchParams, config: FetchConfig,
         mjx_model: mjx.Model, ws_low: jax.Array, ws_high: jax.Array):
    """(next state, reward, terminated, truncated, info) of one env step (``config.physics``
    substeps). ``ws_low``/``ws_high``: the workspace box the mocap target is clamped to.

    info: ``score``, ``success`` (the same: the trainers' per-episode success of the root
    option), ``is_success`` (every block placed), ``placed`` bool[N], ``physics_diverged``.
    """
    num_blocks = config.num_blocks
    action = jnp.clip(jnp.asarray(action, jnp.float32).reshape(4), -1.0, 1.0)
    data = state.data
    old_target = data.mocap_pos[0]
    new_target = jnp.clip(old_target + params.action_scale * action[:3], ws_low, ws_high)
    ctrl = jnp.clip(data.ctrl + fm.FINGER_RANGE[1] * action[3],
                    fm.FINGER_RANGE[0], fm.FINGER_RANGE[1])
    data = data.replace(ctrl=ctrl)
    substeps = config.physics.substeps

    def substep(d, frac):
        target = old_target + frac * (new_target - old_target)
        d = d.replace(mocap_pos=target[None, :])
        return mjx.step(mjx_model, d), None

    fracs = jnp.arange(1, substeps + 1, dtype=jnp.float32) / substeps
    data, _ = jax.lax.scan(substep, data, fracs)
    new_state = FetchState(data=data, goals=state.goals, step=state.step + 1,
                           placed=state.placed)
    placed = blocks_placed(new_state, params)
    new_state = new_state.replace(placed=placed)
    r = reward(new_state, params)
    # MJX has no divergence check of its own: a block squeezed between the fingers can
    # blow up to inf/NaN, which would poison every learner fed this observation. Such
    # an episode terminates (the auto-reset replaces it) with a finite observation and
    # no reward and no score (a zero reward would read as "all placed"), and says so in
    # info["physics_diverged"].
    diverged = ~(jnp.isfinite(data.qpos).all() & jnp.isfinite(data.qvel).all()
                 & (jnp.abs(data.qvel).max() < 1e3))
    episode_score = jnp.where(diverged, 0.0, score(r, num_blocks))
    r = jnp.where(diverged, 0.0, r)
    truncated = new_state.step >= params.max_steps
    info = {
        "score": episode_score,
        # the trainers' per-episode success of the root option: the paper's score
        "success": episode_score,
        "is_success": jnp.all(placed),
        "placed": placed,
        "physics_diverged": diverged,
    }
    return new_state, r, diverged, truncated, info
