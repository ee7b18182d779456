"""The Fetch & Stack scene as MJCF built in code, for N = 1..6 blocks.

Geometry follows the reference (docs/environments.md, Fetch): a table whose top is at
z = 0.4 (box at (1.3, 0.75, 0.2), half-size (0.25, 0.35, 0.2)), 5 cm blocks of mass 2
with free joints, and a gripper that starts at ~(1.3419, 0.7491, 0.555).

Choices made for MJX speed, each checked for fidelity in ``tests/test_fetch_physics.py``:

* **Floating gripper, no arm meshes.** A mocap body is welded to a free gripper body
  (palm + two box fingers on slide joints, position actuators with kp 30000), so the
  control interface (move the grip point, open/close) is the reference's.
* **Table collision is a plane at the table top.** A plane-box contact is far cheaper
  than box-box; the visual table is an ordinary box without collision. The gripper's
  workspace box keeps the fingers inside the table's footprint, so a block can only be
  pushed a few centimetres past the gripper's reach, still on the real table top.
* **Explicit contact pairs only** (block-table, block-block, finger-block): nothing else
  is tested for collision (the palm, which never reaches a block top because the
  fingers hang below it, collides with nothing).
* **Timestep 0.005 s x 8 substeps = 0.04 s per env step** (the reference: 0.002 x 20),
  implicitfast integration so the stiff finger servos stay stable at that step, Newton
  solver with few iterations.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

MIN_BLOCKS, MAX_BLOCKS = 1, 6
BLOCK_HALF = 0.025
BLOCK_MASS = 2.0
TABLE_TOP_Z = 0.4
#: Height of a block's centre when it rests on the table.
BLOCK_REST_Z = TABLE_TOP_Z + BLOCK_HALF
GRIPPER_START = (1.3419, 0.7491, 0.555)
FINGER_RANGE = (0.0, 0.05)
FINGER_KP = 30000.0
# MuJoCo's soft contacts yield in proportion to the *acceleration* pushed into them, so
# light fingers driven by a strong servo sink centimetres into a block. Reflected inertia
# (armature, as a real finger drive has) and a force limit keep the squeeze at ~60 N
# (friction 1: 120 N of hold against a 20 N block) with ~3 mm of penetration; kv sets
# the closing speed (~0.12 m/s: about five env steps to close, like the reference).
FINGER_ARMATURE = 2.0
FINGER_KV = 500.0
FINGER_FORCE = 60.0
# Contact pairs: a stiffer constraint than the default (time constant 0.01 s = 2 physics
# steps) so blocks rest within ~1 mm of their nominal height; the grip contacts also
# use a hard impedance, as the reference's fingers do.
STIFF_CONTACT = 'solref="0.01 1"'
GRIP_CONTACT = 'solref="0.01 1" solimp="0.99 0.99 0.01"'
#: Fingers: half-sizes (x, y, z) and the z of their centre relative to the grip point.
FINGER_HALF = (0.015, 0.008, 0.025)
FINGER_Z = 0.005
#: Workspace of the grip point (mocap target clamp): start xy +- WORKSPACE_XY,
#: z from just above the table (finger bottoms 5 mm above the top) to 0.9.
WORKSPACE_XY = 0.2
WORKSPACE_Z = (BLOCK_REST_Z, 0.9)

BLOCK_COLORS = ("1 0.2 0.2 1", "0.2 0.8 0.2 1", "0.2 0.4 1 1", "1 0.8 0.1 1",
                "0.8 0.3 0.9 1", "0.1 0.8 0.8 1")


@dataclass(frozen=True)
class PhysicsConfig:
    """Static physics settings (they change array shapes or the compiled program)."""

    timestep: float = 0.005
    substeps: int = 8
    solver_iterations: int = 4
    ls_iterations: int = 8

    def __post_init__(self):
        if self.timestep <= 0 or self.substeps < 1:
            raise ValueError(
                f"timestep must be > 0 and substeps >= 1, got {self.timestep}, {self.substeps}"
            )

    @property
    def control_dt(self) -> float:
        return self.timestep * self.substeps


def check_num_blocks(num_blocks: int) -> int:
    if not isinstance(num_blocks, (int, np.integer)) or not (
        MIN_BLOCKS <= int(num_blocks) <= MAX_BLOCKS
    ):
        raise ValueError(
            f"num_blocks must be an integer in {MIN_BLOCKS}..{MAX_BLOCKS}, got {num_blocks!r}"
        )
    return int(num_blocks)


def block_xml(i: int) -> str:
    """Block ``i``'s body: a free box (its pose a placeholder: reset samples it)."""
    return (
        f'<body name="block{i}" pos="{1.2 + 0.06 * i} 0.6 {BLOCK_REST_Z}">'
        f'<freejoint name="block{i}"/>'
        f'<geom name="block{i}" type="box" size="{BLOCK_HALF} {BLOCK_HALF} {BLOCK_HALF}" '
        f'mass="{BLOCK_MASS}" rgba="{BLOCK_COLORS[i]}"/></body>'
    )


def goal_xml(i: int) -> str:
    """Block ``i``'s goal marker: a translucent site in the block's colour."""
    rgba = BLOCK_COLORS[i].rsplit(" ", 1)[0] + " 0.35"
    return f'<site name="goal{i}" pos="1.3 0.75 {0.43 + 0.05 * i}" size="0.02" rgba="{rgba}"/>'


def contact_pairs_xml(n: int) -> list[str]:
    """The only contacts tested: each block with the table top, every earlier block and
    both fingers."""
    pairs = []
    for i in range(n):
        pairs.append(f'<pair geom1="table_top" geom2="block{i}" {STIFF_CONTACT}/>')
        for j in range(i):
            pairs.append(f'<pair geom1="block{j}" geom2="block{i}" {STIFF_CONTACT}/>')
        for finger in ("finger_l", "finger_r"):
            pairs.append(f'<pair geom1="{finger}" geom2="block{i}" {GRIP_CONTACT}/>')
    return pairs


def finger_bodies_xml() -> list[str]:
    """The two fingers: boxes on slide joints, mirrored about the grip point."""
    fx, fy, fz = FINGER_HALF
    return [
        f'<body name="finger_{side}" pos="0 {sign * fy} {FINGER_Z}" gravcomp="1">'
        f'<joint name="finger_{side}" type="slide" axis="0 {sign} 0" '
        f'range="{FINGER_RANGE[0]} {FINGER_RANGE[1]}" armature="{FINGER_ARMATURE}"/>'
        f'<geom name="finger_{side}" type="box" size="{fx} {fy} {fz}" mass="0.1" '
        f'rgba="0.3 0.3 0.3 1"/></body>'
        for side, sign in (("l", 1), ("r", -1))
    ]


def finger_actuators_xml() -> str:
    """The fingers' force-limited position servos."""
    return "".join(
        f'<position name="finger_{s}" joint="finger_{s}" kp="{FINGER_KP}" kv="{FINGER_KV}" '
        f'ctrlrange="{FINGER_RANGE[0]} {FINGER_RANGE[1]}" forcelimited="true" '
        f'forcerange="-{FINGER_FORCE} {FINGER_FORCE}"/>'
        for s in ("l", "r")
    )


def scene_xml(num_blocks: int, physics: PhysicsConfig = PhysicsConfig()) -> str:
    """MJCF text of the scene with ``num_blocks`` blocks."""
    n = check_num_blocks(num_blocks)
    gx, gy, gz = GRIPPER_START
    blocks = [block_xml(i) for i in range(n)]
    goals = [goal_xml(i) for i in range(n)]
    pairs = contact_pairs_xml(n)
    finger_bodies = finger_bodies_xml()
    actuators = finger_actuators_xml()
    return f"""
<mujoco model="fetch_stack{n}">
  <option timestep="{physics.timestep}" integrator="implicitfast" solver="Newton"
          iterations="{physics.solver_iterations}" ls_iterations="{physics.ls_iterations}"
          cone="pyramidal">
    <flag eulerdamp="disable"/>
  </option>
  <default>
    <geom contype="0" conaffinity="0" friction="1 0.005 0.0001" condim="3"/>
  </default>
  <visual><global offwidth="640" offheight="480"/></visual>
  <asset>
    <texture name="grid" type="2d" builtin="checker" rgb1=".85 .85 .85" rgb2=".75 .75 .75"
             width="128" height="128"/>
    <material name="grid" texture="grid" texrepeat="8 8"/>
  </asset>
  <worldbody>
    <light pos="1.3 0.75 2.0" dir="0 0 -1" diffuse="0.8 0.8 0.8"/>
    <geom name="floor" type="plane" size="3 3 0.1" material="grid"/>
    <geom name="table" type="box" pos="1.3 0.75 0.2" size="0.25 0.35 0.2"
          rgba="0.6 0.45 0.3 1"/>
    <geom name="table_top" type="plane" pos="1.3 0.75 {TABLE_TOP_Z}" size="0.25 0.35 0.01"
          rgba="0 0 0 0"/>
    <body name="mocap" mocap="true" pos="{gx} {gy} {gz}"/>
    <body name="gripper" pos="{gx} {gy} {gz}" gravcomp="1">
      <freejoint name="gripper"/>
      <geom name="palm" type="box" pos="0 0 0.04" size="0.02 0.065 0.01" mass="0.5"
            rgba="0.2 0.2 0.2 1"/>
      <site name="grip" pos="0 0 0" size="0.005" rgba="1 0 0 0.5"/>
      {''.join(finger_bodies)}
    </body>
    {''.join(blocks)}
    {''.join(goals)}
  </worldbody>
  <equality>
    <weld body1="mocap" body2="gripper" solref="0.01 1"/>
    <!-- Parallel-jaw coupling: both servos saturate while squeezing, so without it the
         pair of fingers (and the block between them) could slide sideways freely. -->
    <joint joint1="finger_l" joint2="finger_r" solref="0.01 1"/>
  </equality>
  <contact>{''.join(pairs)}</contact>
  <actuator>{actuators}</actuator>
</mujoco>
"""


def build_model(num_blocks: int, physics: PhysicsConfig = PhysicsConfig()) -> mujoco.MjModel:
    """Compiled CPU ``MjModel`` of the scene (put it on the device with ``mjx.put_model``)."""
    return mujoco.MjModel.from_xml_string(scene_xml(num_blocks, physics))


@dataclass(frozen=True)
class ModelIndex:
    """Addresses into qpos/qvel/xpos that the environment reads and writes."""

    num_blocks: int
    gripper_body: int
    grip_site: int
    mocap_id: int
    gripper_qpos: int
    gripper_qvel: int
    finger_qpos: tuple[int, int]
    finger_qvel: tuple[int, int]
    block_body: tuple[int, ...]
    block_qpos: tuple[int, ...]
    block_qvel: tuple[int, ...]
    goal_site: tuple[int, ...]


def model_index(model: mujoco.MjModel, num_blocks: int) -> ModelIndex:
    def body(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)

    def joint(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

    def site(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)

    fingers = [joint("finger_l"), joint("finger_r")]
    blocks = [joint(f"block{i}") for i in range(num_blocks)]
    return ModelIndex(
        num_blocks=num_blocks,
        gripper_body=body("gripper"),
        grip_site=site("grip"),
        mocap_id=int(model.body_mocapid[body("mocap")]),
        gripper_qpos=int(model.jnt_qposadr[joint("gripper")]),
        gripper_qvel=int(model.jnt_dofadr[joint("gripper")]),
        finger_qpos=tuple(int(model.jnt_qposadr[j]) for j in fingers),
        finger_qvel=tuple(int(model.jnt_dofadr[j]) for j in fingers),
        block_body=tuple(body(f"block{i}") for i in range(num_blocks)),
        block_qpos=tuple(int(model.jnt_qposadr[j]) for j in blocks),
        block_qvel=tuple(int(model.jnt_dofadr[j]) for j in blocks),
        goal_site=tuple(site(f"goal{i}") for i in range(num_blocks)),
    )
