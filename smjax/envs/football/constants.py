"""Pitch geometry, formation, action ids, game modes and physics constants.

Coordinates follow Google Research Football (GRF): x in [-1, 1] (left goal at x = -1,
right goal at x = +1), y in [-0.42, 0.42] with y growing *downward* on screen, so
"top" means smaller y. One step is 0.1 s of play. Player 0..10 are the left team
(the agent's), 11..21 the right team; index ``11 * team + i`` is player i of a team.
The right team's formation is the left one reflected through the centre spot
(x, y) -> (-x, -y), which makes the game symmetric under that reflection plus a
swap of the teams.
"""
from __future__ import annotations

import numpy as np

# ---- pitch ---------------------------------------------------------------
FIELD_X = 1.0
FIELD_Y = 0.42
GOAL_HALF_WIDTH = 0.044
GOAL_HEIGHT = 0.05          # crossbar: a ball crossing the line higher than this is out
PENALTY_BOX_X = 0.7         # |x| beyond this and |y| < PENALTY_BOX_Y is a penalty area
PENALTY_BOX_Y = 0.24
PENALTY_SPOT_X = 0.8
CENTRE_CIRCLE = 0.174       # kick-off: the defending team stays outside this radius
RESTART_CLEARANCE = 0.1     # opponents keep this distance from the ball at a restart
PLAYER_BOUND_X = 1.08       # players may step a little outside the lines
PLAYER_BOUND_Y = 0.48

NUM_PLAYERS = 11
NUM_TOTAL = 22

# ---- actions (GRF default action set, plus 19 = built-in AI) ---------------
IDLE, LEFT, TOP_LEFT, TOP, TOP_RIGHT, RIGHT, BOTTOM_RIGHT, BOTTOM, BOTTOM_LEFT = range(9)
LONG_PASS, HIGH_PASS, SHORT_PASS, SHOT = 9, 10, 11, 12
SPRINT, RELEASE_DIRECTION, RELEASE_SPRINT, SLIDING, DRIBBLE, RELEASE_DRIBBLE = 13, 14, 15, 16, 17, 18
BUILTIN_AI = 19
NUM_ACTIONS = 19
ACTION_NAMES = (
    "idle", "left", "top_left", "top", "top_right", "right", "bottom_right", "bottom",
    "bottom_left", "long_pass", "high_pass", "short_pass", "shot", "sprint",
    "release_direction", "release_sprint", "sliding", "dribble", "release_dribble",
    "builtin_ai",
)

_S = float(np.sqrt(0.5))
# Unit vector of each sticky direction (index 0 = no direction). y grows downward, so
# "top" is (0, -1): pressing TOP moves a player toward smaller y (GRF's convention; the
# paper's reference code had top and bottom swapped, smjax does not).
DIRECTION_VECTORS = np.array(
    [
        [0.0, 0.0],    # none
        [-1.0, 0.0],   # left
        [-_S, -_S],    # top-left
        [0.0, -1.0],   # top
        [_S, -_S],     # top-right
        [1.0, 0.0],    # right
        [_S, _S],      # bottom-right
        [0.0, 1.0],    # bottom
        [-_S, _S],     # bottom-left
    ],
    np.float32,
)

# ---- game modes (GRF e_GameMode order) -------------------------------------
NORMAL, KICK_OFF, GOAL_KICK, FREE_KICK, CORNER, THROW_IN, PENALTY = range(7)
NUM_GAME_MODES = 7
GAME_MODE_NAMES = ("normal", "kick_off", "goal_kick", "free_kick", "corner", "throw_in", "penalty")
RESTART_MAX_TICKS = 30      # a restart taker who has not kicked by then just plays on

# ---- formation (left team, GRF 11_vs_11 kick-off positions) ------------------
FORMATION = np.array(
    [
        [-1.0, 0.0],
        [0.0, 0.02],
        [0.0, -0.02],
        [-0.422, -0.19576],
        [-0.5, -0.06356],
        [-0.5, 0.063559],
        [-0.422, 0.19576],
        [-0.184212, -0.10568],
        [-0.267574, 0.0],
        [-0.184212, 0.10568],
        [-0.01, -0.2161],
    ],
    np.float32,
)
# Where the two centre players of the team *not* kicking off stand (outside the circle).
KICKOFF_DEFENDER_SPOTS = np.array([[-0.2, 0.05], [-0.2, -0.05]], np.float32)

# GRF e_PlayerRole ids: GK 0, CB 1, LB 2, RB 3, DM 4, CM 5, LM 6, RM 7, AM 8, CF 9.
ROLE_NAMES = ("GK", "CB", "LB", "RB", "DM", "CM", "LM", "RM", "AM", "CF")
ROLES = np.array([0, 9, 8, 2, 1, 1, 3, 5, 4, 5, 6], np.int32)
GOALKEEPER = 0              # index of the goalkeeper within a team

# ---- physics (units per step; 1 x-unit = 52.5 m, a step = 0.1 s) ----------------
RUN_SPEED = 0.008
SPRINT_SPEED = 0.0125
DRIBBLE_SPEED = 0.0075
CARRIER_SPEED_FACTOR = 0.9   # running with the ball is a little slower
ACCELERATION = 0.35          # fraction of the gap to the desired velocity closed per step
SLIDE_SPEED = 0.02
SLIDE_STUN = 12              # ticks a sliding player lies on the ground
BALL_OFFSET = 0.012          # a controlled ball sits this far in front of the carrier
GRAVITY = 0.0019
GROUND_FRICTION = 0.035      # rolling ball keeps (1 - friction) of its speed per step
AIR_DRAG = 0.005
BOUNCE = 0.45                # vertical speed kept after a bounce
BOUNCE_SPEED_KEPT = 0.8      # horizontal speed kept after a bounce
MAX_KICK_SPEED = 0.06
SHOT_SPEED = 0.062
SHOT_LIFT = 0.006
LONG_PASS_APEX = 0.05
HIGH_PASS_APEX = 0.15
PASS_BASE_SPEED = 0.02       # ground pass speed = base + gain * distance (capped); it
PASS_SPEED_GAIN = 0.05       # always rolls past a receiver who stands still
KICK_COOLDOWN = 6            # a kicker cannot touch the ball again for this many ticks
TACKLED_COOLDOWN = 10        # a dispossessed carrier cannot touch the ball for this long

CONTROL_RADIUS = 0.02
CONTROL_HEIGHT = 0.05
GK_CONTROL_RADIUS = 0.035    # a goalkeeper inside his own penalty area dives and catches
GK_CONTROL_HEIGHT = 0.12
TACKLE_RADIUS = 0.022
SLIDE_RADIUS = 0.04
STANDING_TACKLE_PROB = 0.1   # per tick, per defender within TACKLE_RADIUS of the ball
DRIBBLE_TACKLE_FACTOR = 0.5  # dribbling halves a standing tackle's chance
SLIDE_TACKLE_PROB = 0.65     # a sliding tackle that reaches the ball and fails is a foul

# ---- reward shaping --------------------------------------------------------
NUM_CHECKPOINTS = 10
CHECKPOINT_REWARD = 0.1
CHECKPOINT_THRESHOLDS = np.array([0.99 - 0.8 * k / 9 for k in range(NUM_CHECKPOINTS)], np.float32)

# ---- random draws per tick (see types.Noise) --------------------------------
NUM_UNIFORM = 8
NUM_NORMAL = 3
