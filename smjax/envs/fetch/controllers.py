"""Scripted controllers for the stacking templates: smooth proportional control.

Every controller is a pure function of (state, params, block index) returning
float32[4] in [-1, 1]; the block index is a Python int (one controller per template).

Gains: the movement command is ``clip(GAIN * error, -1, 1)``; with 0.05 m per unit of
action a gain of 15 closes 75 % of the error per step, far from the error and at full
speed (5 cm/step), near it smoothly (no integer truncation, unlike the reference's
bang-bang commands); carrying is capped at 3 cm per step. ``DEAD_BAND`` (0.02 m;
0.01 m for the reach's descent) decides when xy counts as reached, which switches
phases (xy before z); inside a phase every axis keeps being corrected proportionally
so small errors do not persist.

Templates are pure functions of (key, state, params), so a controller cannot count
steps. Its phase is derived from the state instead (the finger servo target
``data.ctrl`` and the finger joint positions/velocities are part of the state):

* *closing* (replaces the reference's "close for 5 steps"): block i is between the
  fingertips (``||block - grip|| < REACH_TOL``) but not yet held: hold still, close.
* *held* (``is_gripping``): fingers commanded shut, stopped at a block-wide gap
  (``GRIP_GAP``), block within ``HOLD_TOL`` of the grip; carrying starts once the
  fingers have also stopped moving (``fingers_settled``), i.e. the squeeze is on.
* *stuck*: commanded shut but held wider than a block (a finger sits on a neighbour):
  open and rise, then reach again.
* *opening* (replaces "open for 5 steps"): release keeps the arm still until the
  finger gap is nearly fully open, then lifts.

Geometry-aware touches that the reference controllers lack, each because a grasp fails
without it: the reach opens the fingers only to a 7.6 cm gap, grasps a
block off-centre along x when a neighbour lies in the fingers' path
(``grasp_offset``), and rises above any block it is still straddling before moving
sideways (otherwise the block just released on the tower is dragged off).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.fetch import types as st
from smjax.envs.fetch.model import BLOCK_HALF, FINGER_RANGE
from smjax.envs.fetch.types import FetchParams, FetchState

GAIN = 15.0
DEAD_BAND = 0.02
#: Termination tests (docs/environments.md, Fetch): reached, placed (by pick), released.
REACH_TOL = 0.03
PLACE_TOL = 0.03
RELEASE_HEIGHT = 0.05
#: Carry height above the goal and the height release lifts to (at least).
CARRY_HEIGHT = 0.1
LIFT_Z = 0.65
#: Finger opening thresholds (each finger 0 .. 0.05; the block's half width is 0.025).
#: A gap this wide (just under the block's width, which the soft contact lets the fingers
#: sink a few mm into, up to a little over it) means the fingers are stopped by a block.
GRIP_GAP = (2 * BLOCK_HALF - 0.012, 2 * BLOCK_HALF + 0.006)
#: A held block may sit this far from the grip point (it can slide a little in the fingers).
HOLD_TOL = 0.05
#: Finger speed (m/s) below which a closing grasp counts as finished.
SETTLED_SPEED = 0.02
#: Controllers open each finger only this far (gap 0.076: 1.3 cm of clearance per side)
#: rather than fully (0.1), so opening next to a neighbouring block or the tower pushes
#: it less; the reach descends only once xy is within ``REACH_XY_BAND``.
OPEN_FINGER = 0.038
REACH_XY_BAND = 0.01
OPEN, CLOSE = 1.0, -1.0
#: Neighbour avoidance when grasping (see ``grasp_offset``): a block closer than
#: FINGER_ZONE_Y along y is in the fingers' path when its x-distance is below
#: FINGER_CLEAR_X (finger half-width 0.015 + block half-width 0.025 + 5 mm).
FINGER_ZONE_Y = 0.085
FINGER_CLEAR_X = 0.045
MAX_GRASP_SHIFT = 0.025
#: Grip height above a block's centre at which the fingertips clear its top (0.045 + margin).
CLEAR_ABOVE = 0.06
#: Carrying moves at most 3 cm per step: sharper accelerations make the block swivel in
#: the fingers.
CARRY_SPEED = 0.6


def _command(error: jax.Array, fingers: float | jax.Array, speed: float = 1.0) -> jax.Array:
    move = jnp.clip(GAIN * error, -speed, speed)
    return jnp.concatenate([move, jnp.reshape(jnp.asarray(fingers, jnp.float32), (1,))])


def _open_command(state: FetchState) -> jax.Array:
    # The finger action moves the servo target by 0.05 m per unit: steer it to OPEN_FINGER.
    target = jnp.mean(state.data.ctrl)
    return jnp.clip((OPEN_FINGER - target) / FINGER_RANGE[1], -1.0, 1.0)


def _lift_z(state: FetchState) -> jax.Array:
    # High enough that the gripper ends more than 0.08 m from every goal, towers of 4+ included.
    return jnp.maximum(LIFT_Z, jnp.max(state.goals[:, 2]) + CARRY_HEIGHT)


def block_to_grip(state: FetchState, i: int) -> jax.Array:
    return jnp.linalg.norm(st.block_pos(state)[i] - st.gripper_pos(state))


def block_to_goal(state: FetchState, i: int) -> jax.Array:
    return jnp.linalg.norm(st.block_pos(state)[i] - state.goals[i])


def finger_gap(state: FetchState) -> jax.Array:
    """Distance between the fingertips' inner faces (0 .. 0.1)."""
    return jnp.sum(st.finger_qpos(state))


def fingers_settled(state: FetchState) -> jax.Array:
    return jnp.max(jnp.abs(st.finger_qvel(state))) < SETTLED_SPEED


def is_reached(state: FetchState, i: int) -> jax.Array:
    return block_to_grip(state, i) < REACH_TOL


def is_gripping(state: FetchState, i: int) -> jax.Array:
    """Block i held: fingers commanded shut, stopped by a block-wide gap, block at the grip."""
    gap = finger_gap(state)
    block_wide = (gap > GRIP_GAP[0]) & (gap < GRIP_GAP[1])
    commanded_shut = jnp.max(state.data.ctrl) < 0.01
    return block_wide & commanded_shut & (block_to_grip(state, i) < HOLD_TOL)


def grasp_offset(state: FetchState, i: int) -> jax.Array:
    """float32[3]: where to grasp block i relative to its centre, to keep fingers off neighbours.

    The fingers close along y and are 3 cm wide in x, so a neighbour lying beside block i
    along y (|dy| < ``FINGER_ZONE_Y``) and overlapping the fingers in x would be hit by a
    finger coming down. Grasping block i off-centre along x (up to ``MAX_GRASP_SHIFT``,
    which leaves 1.5 cm of finger on the block) moves the fingers away from it.
    """
    blocks = st.block_pos(state)
    rel = blocks - blocks[i]
    others = jnp.arange(blocks.shape[0]) != i
    beside = (jnp.abs(rel[:, 1]) < FINGER_ZONE_Y) & (jnp.abs(rel[:, 2]) < 0.06) & others
    overlap = jnp.maximum(FINGER_CLEAR_X - jnp.abs(rel[:, 0]), 0.0)
    push = jnp.where(beside, -jnp.sign(rel[:, 0]) * overlap, 0.0)
    shift = jnp.clip(jnp.sum(push), -MAX_GRASP_SHIFT, MAX_GRASP_SHIFT)
    return jnp.stack([shift, 0.0, 0.0])


def is_stuck(state: FetchState, i: int) -> jax.Array:
    """Fingers commanded shut at block i but held open wider than it (a finger sits on
    something): closing further cannot succeed, so back off and reach again."""
    return (is_reached(state, i) & (jnp.max(state.data.ctrl) < 0.01)
            & (finger_gap(state) > GRIP_GAP[1]) & fingers_settled(state))


def reach(state: FetchState, params: FetchParams, i: int) -> jax.Array:
    """Open the fingers, move over block i (never descending while xy is off), then down."""
    grip = st.gripper_pos(state)
    block = st.block_pos(state)[i] + grasp_offset(state, i)
    err = block - grip
    xy_off = jnp.linalg.norm(err[:2]) > REACH_XY_BAND
    # While xy is off, hold (or regain) a height where the fingertips clear the block tops.
    hover_z = jnp.maximum(grip[2], block[2] + 2 * BLOCK_HALF)
    z_err = jnp.where(xy_off, hover_z - grip[2], err[2])
    # Fingers still around another block (e.g. the one just released on the tower):
    # rise above it before any sideways move, or it is dragged along.
    blocks = st.block_pos(state)
    others = jnp.arange(blocks.shape[0]) != i
    around = others & (jnp.linalg.norm(blocks[:, :2] - grip[:2], axis=-1) < 0.08)
    clear_z = jnp.max(jnp.where(around, blocks[:, 2] + CLEAR_ABOVE, -jnp.inf))
    trapped = xy_off & (grip[2] < clear_z - 0.005)
    move_xy = jnp.where(trapped, jnp.zeros(2), err[:2])
    z_err = jnp.where(trapped, clear_z - grip[2], z_err)
    return _command(jnp.concatenate([move_xy, z_err[None]]), _open_command(state))


def carry(state: FetchState, params: FetchParams, i: int) -> jax.Array:
    """With block i held: lift to goal + carry height, move over the goal, lower onto it.

    The errors are measured on the block (not the grip point), so a block that slipped
    in the fingers is still put where it belongs.
    """
    block = st.block_pos(state)[i]
    goal = state.goals[i]
    err = goal - block
    xy_off = jnp.linalg.norm(err[:2]) > DEAD_BAND
    carry_z = goal[2] + CARRY_HEIGHT
    low = block[2] < carry_z - DEAD_BAND
    # Lift first (xy frozen) so the block clears the tower, then xy at height, then lower.
    move_xy = jnp.where(xy_off & low, jnp.zeros(2), err[:2])
    z_err = jnp.where(xy_off, carry_z - block[2], err[2])
    return _command(jnp.concatenate([move_xy, z_err[None]]), CLOSE, CARRY_SPEED)


def pick(state: FetchState, params: FetchParams, i: int) -> jax.Array:
    """Close on block i, then carry it onto its goal; re-reach it if it is not in the fingers.

    If the closing fingers are blocked (``is_stuck``), open and rise 5 cm, after which
    the reach comes down again (with the neighbour-avoiding grasp offset).
    """
    gripping = is_gripping(state, i)
    carrying = gripping & fingers_settled(state)
    closing = (is_reached(state, i) | gripping) & ~carrying
    hold_still = _command(jnp.zeros(3), CLOSE)
    back_off = jnp.asarray([0.0, 0.0, 1.0, OPEN], jnp.float32)
    action = jnp.where(carrying, carry(state, params, i),
                       jnp.where(closing, hold_still, reach(state, params, i)))
    return jnp.where(is_stuck(state, i), back_off, action)


def release(state: FetchState, params: FetchParams, i: int) -> jax.Array:
    """Open the fingers (arm still), then lift straight up to the lift height."""
    grip = st.gripper_pos(state)
    opened = finger_gap(state) > 2 * (FINGER_RANGE[1] - 0.006)
    lift = jnp.stack([0.0, 0.0, _lift_z(state) - grip[2]])
    # Open fully here: a block that swivelled in the grip is wider than the reach opening.
    return jnp.where(opened, _command(lift, OPEN), _command(jnp.zeros(3), OPEN))


def place(state: FetchState, params: FetchParams, i: int) -> jax.Array:
    """Level 1: reach -> pick & carry -> release as one controller, phase read off the state.

    Release once the block is on its goal (within ``PLACE_TOL``) or, no longer held,
    within the success distance; otherwise pick (which reaches first when needed).
    """
    dist = block_to_goal(state, i)
    held = is_gripping(state, i)
    on_goal = (dist < PLACE_TOL) | ((dist < params.success_distance) & ~held)
    return jnp.where(on_goal, release(state, params, i), pick(state, params, i))


def noop(state: FetchState, params: FetchParams) -> jax.Array:
    return jnp.zeros(4, jnp.float32)
