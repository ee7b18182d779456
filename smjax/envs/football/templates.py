"""Option templates for football as scripted controllers, and the paper's hierarchies.

Every controller returns i32[11] actions for the left team; players a template does
not direct get 19 (the built-in AI). Directions are GRF's: y grows downward, TOP (3)
moves toward smaller y (the reference code had top and bottom swapped).

"We have the ball" means a left player controls it, or it is in flight to a left
receiver after our pass. "Lost" means a right player controls it (this includes the
kick-off after we score, which the opponents take).

* ``attack`` (attack and score): charge when the carrier's x >= 0.5, shoot within
  0.25 of (1, 0), else maintain possession. Initiation: we have the ball. Satisfied:
  we scored (the tick our goal goes in); failed: the opponents control the ball.
* ``defend``: the built-in AI (pressing, formation) for all 11 until we win the ball.
  Initiation: we do not have the ball. Satisfied: we have it.
* ``maintain_possession``: the carrier sprints with the ball in the free direction
  that gains most ground (no opponent within 0.2 ahead in a 30-degree cone; only
  directions within ~72 degrees of the goal count), the two wide players run to
  support spots on the wings; with no free direction he passes to the teammate whose
  lane has the fewest possible interceptors (within 0.04 of it), then the most
  forward and open one: short pass below 0.4, long beyond, high when the lane is not
  clear. Initiation: the opponents do not control the ball (we have it, or it is
  loose: then it is the one child of ``attack`` available, so an attack goes on
  through a loose ball instead of leaving its learner no allowed choice). Satisfied:
  our carrier reaches x >= 0.5; failed: the opponents control the ball.
* ``charge``: the carrier sprints toward (1, 0). Initiation: a left player controls
  the ball. Satisfied: a left carrier within 0.3 of (1, 0); failed: we no longer
  control the ball.
* ``shoot``: the carrier shoots. Initiation: a left player controls the ball.
  Satisfied: no left player controls it (the ball has left the shooter).
All time out after 200 ticks (k_max). While no left player controls the ball every
controller hands all 11 players to the built-in AI (it chases loose balls and runs onto
our passes); directing "the carrier" then would move the goalkeeper.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.envs.football import constants as C
from smjax.envs.football.builtin_ai import lane_blockers, quantize_direction
from smjax.envs.football.physics import DIRS, dot2, norm2
from smjax.envs.football.types import FootballState
from smjax.options import OptionTemplate, declare

K_MAX = 200
# numpy, so that importing runs no XLA program (see physics.DIRS)
GOAL = np.array([1.0, 0.0], np.float32)
_N = C.NUM_PLAYERS
_DIRS8 = DIRS[1:]


def left_controls(state: FootballState) -> jax.Array:
    return (state.owner >= 0) & (state.owner < _N)


def right_controls(state: FootballState) -> jax.Array:
    return state.owner >= _N


def we_have_ball(state: FootballState) -> jax.Array:
    in_flight_to_us = (state.owner < 0) & (state.pass_receiver >= 0) & (state.pass_receiver < _N)
    return left_controls(state) | in_flight_to_us


def _carrier(state: FootballState) -> jax.Array:
    return jnp.where(left_controls(state), state.owner, 0)


def steer(state: FootballState, player: jax.Array, direction: jax.Array, sprint: jax.Array) -> jax.Array:
    """The one action that moves ``player`` toward running ``direction`` (1..8) with sprint."""
    cur_dir, cur_sprint = state.sticky_dir[player], state.sprint[player]
    return jnp.where(direction != cur_dir, direction,
                     jnp.where(sprint != cur_sprint, jnp.where(sprint, C.SPRINT, C.RELEASE_SPRINT),
                               jnp.where(state.dribble[player], C.RELEASE_DRIBBLE, C.IDLE)))


def _kick_toward(state: FootballState, player: jax.Array, direction: jax.Array, kick: jax.Array) -> jax.Array:
    """Turn toward ``direction`` first; kick once the player aims that way."""
    aim = jnp.where(state.sticky_dir[player] > 0, state.sticky_dir[player],
                    quantize_direction(state.facing[player]))
    return jnp.where(aim == direction, kick, direction)


def _only(player: jax.Array, action: jax.Array) -> jax.Array:
    actions = jnp.full((_N,), C.BUILTIN_AI, jnp.int32)
    return actions.at[player].set(action.astype(jnp.int32))


def _with_ball_only(state: FootballState, actions: jax.Array) -> jax.Array:
    """``actions`` while a left player controls the ball, else the built-in AI for all 11.

    Without a carrier there is nobody to direct (``_carrier`` would name the goalkeeper);
    the AI runs to a loose ball or to our pass's landing point.
    """
    return jnp.where(left_controls(state), actions, jnp.full((_N,), C.BUILTIN_AI, jnp.int32))


# ---- controllers -------------------------------------------------------------
def charge_controller(key: jax.Array, state: FootballState, params) -> jax.Array:
    c = _carrier(state)
    direction = quantize_direction(jnp.asarray(GOAL) - state.pos[c])
    return _with_ball_only(state, _only(c, steer(state, c, direction, jnp.bool_(True))))


def shoot_controller(key: jax.Array, state: FootballState, params) -> jax.Array:
    return _with_ball_only(state, _only(_carrier(state), jnp.int32(C.SHOT)))


# Carrying the ball: how far ahead a direction must be clear of opponents, and how much
# it must gain toward goal (cos of its angle to the goal line of sight: 0.3 ~ 72 degrees).
# Against the hard AI, sideways dribbles and a walking carrier lose the ball (a carrier
# free to walk anywhere concedes about 1.9 goals a game on possession alone); a
# sprinting, goal-ward carrier keeps it.
FREE_LOOKAHEAD = 0.2
FREE_MIN_GAIN = 0.3
# Pass choice: interceptors in the lane count 1 each, then progress (0.5 per unit of x)
# and how open the receiver is (3 per unit of distance to his nearest marker, capped at
# 0.12, so a free man 0.1 ahead beats a marked one 0.5 ahead).
PASS_FORWARD_WEIGHT = 0.5
PASS_OPEN_WEIGHT = 3.0


def possession_actions(state: FootballState) -> jax.Array:
    c = _carrier(state)
    me = state.pos[c]
    own, opp = state.pos[:_N], state.pos[_N:]
    rel = opp - me
    along = dot2(rel[:, None, :], _DIRS8[None])            # [11 opp, 8 dirs]
    across = jnp.sqrt(jnp.maximum(dot2(rel, rel)[:, None] - along**2, 0.0))
    blocked = jnp.any((along > 0.0) & (along < FREE_LOOKAHEAD) & (across < along * 0.577), axis=0)
    probe = me + 0.1 * jnp.asarray(_DIRS8)
    on_pitch = (jnp.abs(probe[:, 1]) < 0.4) & (jnp.abs(probe[:, 0]) < 0.98)
    goal_unit = (jnp.asarray(GOAL) - me) / (norm2(jnp.asarray(GOAL) - me) + 1e-9)
    gain = dot2(jnp.asarray(_DIRS8), goal_unit)
    free = ~blocked & on_pitch & (gain > FREE_MIN_GAIN)
    best_free = (jnp.argmax(jnp.where(free, gain, -10.0)) + 1).astype(jnp.int32)

    interceptors = lane_blockers(me, own, opp, 0.04)
    dist = norm2(own - me)
    mates = jnp.arange(_N)
    mark = own[:, None, :] - opp[None, :, :]
    openness = jnp.sqrt(jnp.min(mark[..., 0] ** 2 + mark[..., 1] ** 2, axis=1))
    # Fewest interceptors first; among equals, the most forward and most open.
    pass_score = (-interceptors.astype(jnp.float32) + PASS_FORWARD_WEIGHT * (own[:, 0] - me[0])
                  + PASS_OPEN_WEIGHT * jnp.minimum(openness, 0.12)
                  - 100.0 * (mates == c) - 100.0 * (mates == C.GOALKEEPER) - 100.0 * (dist < 0.05))
    mate = jnp.argmax(pass_score)
    kind = jnp.where(interceptors[mate] > 0, C.HIGH_PASS,
                     jnp.where(dist[mate] < 0.4, C.SHORT_PASS, C.LONG_PASS))
    pass_action = _kick_toward(state, c, quantize_direction(own[mate] - me), kind)
    # Into free space the carrier sprints: walking pace lets the pressing AI catch him.
    carrier_action = jnp.where(jnp.any(free), steer(state, c, best_free, jnp.bool_(True)), pass_action)

    # Two wingers in support: the two field players furthest out on each flank.
    ball = state.ball_pos[:2]
    field = (mates != C.GOALKEEPER) & (mates != c)
    top = jnp.argmin(jnp.where(field, own[:, 1], 1e9))
    bottom = jnp.argmax(jnp.where(field & (mates != top), own[:, 1], -1e9))
    actions = _only(c, carrier_action)
    for wing, side in ((top, -1.0), (bottom, 1.0)):
        spot = jnp.stack([jnp.clip(ball[0] + 0.15, -0.9, 0.9), side * 0.3])
        delta = spot - own[wing]
        run = jnp.where(norm2(delta) > 0.02, quantize_direction(delta), C.RELEASE_DIRECTION)
        wing_action = jnp.where(run == C.RELEASE_DIRECTION,
                                jnp.where(state.sticky_dir[wing] > 0, C.RELEASE_DIRECTION, C.IDLE),
                                steer(state, wing, run, jnp.bool_(True)))
        actions = actions.at[wing].set(wing_action.astype(jnp.int32))
    return actions


def maintain_possession_controller(key: jax.Array, state: FootballState, params) -> jax.Array:
    return _with_ball_only(state, possession_actions(state))


def attack_controller(key: jax.Array, state: FootballState, params) -> jax.Array:
    c = _carrier(state)
    x, dist_goal = state.pos[c, 0], norm2(state.pos[c] - jnp.asarray(GOAL))
    shoot = shoot_controller(key, state, params)
    charge = charge_controller(key, state, params)
    keep = possession_actions(state)
    chosen = jnp.where(dist_goal < 0.25, shoot, jnp.where(x >= 0.5, charge, keep))
    # While our pass is in flight nobody controls the ball: let the AI run to it.
    return _with_ball_only(state, chosen)


def defend_controller(key: jax.Array, state: FootballState, params) -> jax.Array:
    return jnp.full((_N,), C.BUILTIN_AI, jnp.int32)


# ---- conditions ----------------------------------------------------------------
def we_just_scored(state: FootballState) -> jax.Array:
    """The tick our goal went in: the opponents are set to kick off, timer at 0 (their
    kick-offs happen only after our goals; the match starts with ours)."""
    return (state.game_mode == C.KICK_OFF) & (state.mode_timer == 0) & right_controls(state)


def attack_satisfied(state: FootballState, params) -> jax.Array:
    """F_o of "attack and score": we scored."""
    return we_just_scored(state)


def attack_failed(state: FootballState, params) -> jax.Array:
    """The attack ends without its outcome when the opponents win the ball."""
    return right_controls(state) & ~we_just_scored(state)


def possession_satisfied(state: FootballState, params) -> jax.Array:
    return left_controls(state) & (state.pos[_carrier(state), 0] >= 0.5)


def possession_failed(state: FootballState, params) -> jax.Array:
    return right_controls(state)


def charge_satisfied(state: FootballState, params) -> jax.Array:
    near = norm2(state.pos[_carrier(state)] - jnp.asarray(GOAL)) <= 0.3
    return left_controls(state) & near


def charge_failed(state: FootballState, params) -> jax.Array:
    return ~left_controls(state)


def defend_satisfied(state: FootballState, params) -> jax.Array:
    return we_have_ball(state)


def _we_have(state, params):
    return we_have_ball(state)


def _we_do_not_have(state, params):
    return ~we_have_ball(state)


def _we_control(state, params):
    return left_controls(state)


def _they_do_not_control(state, params):
    return ~right_controls(state)


def make_templates() -> dict[str, OptionTemplate]:
    # (name, satisfied = F_o, failed = ends without the outcome, initiation, controller, doc)
    specs = [
        ("attack", attack_satisfied, attack_failed, _we_have, attack_controller,
         "attack and score (fails when the ball is lost)"),
        ("defend", defend_satisfied, None, _we_do_not_have, defend_controller,
         "built-in defence until the ball is won"),
        ("maintain_possession", possession_satisfied, possession_failed, _they_do_not_control,
         maintain_possession_controller, "dribble into space or pass safely until x >= 0.5"),
        ("charge", charge_satisfied, charge_failed, _we_control, charge_controller,
         "carrier sprints toward the goal until within 0.3"),
        ("shoot", lambda s, p: ~left_controls(s), None, _we_control, shoot_controller, "shoot at goal"),
    ]
    return {
        name: OptionTemplate(name=name, satisfied=sat, failed=fail, k_max=K_MAX, initiation=init,
                             controller=ctrl, description=desc)
        for name, sat, fail, init, ctrl, desc in specs
    }


def make_hierarchies(env) -> dict:
    paper = declare(env, "win_game", {
        "win_game": ["attack", "defend"],
        "attack": ["maintain_possession", "charge", "shoot"],
    })
    # flat: win_game -> maintain_possession, charge, shoot, defend
    return {"paper": paper, "flat": paper.flattened()}
