"""One tick of the match: kicks, tackles, ball control, goals, out of play, restarts.

Rules chosen (beyond physics.py):

* **Possession.** A loose ball is controlled by the nearest player whose reach
  (CONTROL_RADIUS; a goalkeeper inside his own penalty area: GK_CONTROL_RADIUS and
  GK_CONTROL_HEIGHT, he uses his hands) touches the ball's path this step, if the ball
  is low enough and a control roll succeeds: p = clip(1.4 - 16 |v|, 0.25, 1) for field
  players, clip(1.3 - 12 |v|, 0.35, 1) for keepers, so slow passes are almost always
  controlled and hard shots often get through. Any player, teammate or opponent, can
  take a ball this way: that is how interceptions and saves happen (a keeper who
  catches it turns to face the play, so he never holds it over his own line). A
  player who just kicked (KICK_COOLDOWN) or was dispossessed (TACKLED_COOLDOWN)
  cannot touch it.
* **Tackles.** Every opponent within TACKLE_RADIUS of a controlled ball wins it with
  probability 0.2 per tick (0.1 if the carrier dribbles). A sliding tackle (action 16)
  lunges the player forward, reaches SLIDE_RADIUS and wins the ball with probability
  0.65; a slide that reaches the ball and fails is a foul: a free kick to the fouled
  team at the ball, or a penalty if it happened in the slider's own penalty area. A
  slider is on the ground for SLIDE_STUN ticks. The nearest successful tackler wins.
* **Goals** count when the ball crosses the goal line between the posts under the
  crossbar (interpolated at the crossing point); the conceding team kicks off, both
  teams back in formation.
* **Out of play.** Over the side line: throw-in to the team that did not touch it last.
  Over a goal line outside the goal: a corner if the defending team touched it last,
  else a goal kick taken by that team's goalkeeper at 0.9 from its goal.
* **Restarts** (kick-off, goal kick, free kick, corner, throw-in, penalty): the nearest
  player of the restarting team (goalkeeper for a goal kick, never him otherwise) is put
  on the spot with the ball; he cannot move but may turn and must kick; opponents are
  kept RESTART_CLEARANCE from the ball and cannot tackle. The mode returns to normal
  when the ball is kicked, or after RESTART_MAX_TICKS (then he simply plays on). For a
  penalty the defending goalkeeper is put on his goal line.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.env import select_tree
from smjax.envs.football import constants as C
from smjax.envs.football import physics
from smjax.envs.football.physics import norm2
from smjax.envs.football.reset import kickoff
from smjax.envs.football.types import FootballState, Noise, player_team, team_sign

# numpy (see physics.DIRS): taken with jnp.asarray where used
_IDX = np.arange(C.NUM_TOTAL, dtype=np.int32)
_TEAM_OF = _IDX // C.NUM_PLAYERS
_IS_GK = (_IDX % C.NUM_PLAYERS) == C.GOALKEEPER
_INF = np.float32(1e9)


def in_own_penalty_area(pos: jax.Array, team: jax.Array) -> jax.Array:
    """Whether points f32[..., 2] lie in the penalty area that ``team`` defends."""
    own_x = -team_sign(team) * pos[..., 0]
    return (own_x > C.PENALTY_BOX_X) & (jnp.abs(pos[..., 1]) < C.PENALTY_BOX_Y)


def _push_out(pos: jax.Array, centre: jax.Array, mask: jax.Array, radius: float, fallback: jax.Array):
    """Move masked players closer than ``radius`` to ``centre`` onto that circle."""
    delta = pos - centre
    dist = norm2(delta)
    unit = jnp.where(dist[:, None] > 1e-6, delta / (dist[:, None] + 1e-9), fallback)
    bound = jnp.array([C.PLAYER_BOUND_X, C.PLAYER_BOUND_Y])
    pushed = jnp.clip(centre + unit * radius, -bound, bound)
    return jnp.where((mask & (dist < radius))[:, None], pushed, pos)


def apply_restart(state: FootballState, mode: jax.Array, team: jax.Array, spot: jax.Array) -> FootballState:
    """Set up a non-kick-off restart of ``mode`` for ``team`` with the ball at ``spot``."""
    sign = team_sign(team)
    mine = jnp.asarray(_TEAM_OF) == team
    may_take = jnp.where(mode == C.GOAL_KICK, mine & jnp.asarray(_IS_GK), mine & ~jnp.asarray(_IS_GK))
    dist = norm2(state.pos - spot)
    taker = jnp.argmin(jnp.where(may_take, dist, _INF)).astype(jnp.int32)
    look_at = jnp.where(mode == C.PENALTY, jnp.stack([sign, 0.0]), jnp.stack([sign * 0.5, 0.0]))
    facing = (look_at - spot) / (norm2(look_at - spot) + 1e-9)
    pos = state.pos.at[taker].set(spot - facing * C.BALL_OFFSET)
    pos = _push_out(pos, spot, ~mine, C.RESTART_CLEARANCE, -facing)
    keeper = C.NUM_PLAYERS * (1 - team) + C.GOALKEEPER
    pos = jnp.where(mode == C.PENALTY, pos.at[keeper].set(jnp.stack([sign * 0.99, 0.0])), pos)
    return state.replace(
        pos=pos,
        vel=state.vel.at[taker].set(0.0),
        facing=state.facing.at[taker].set(facing),
        sticky_dir=state.sticky_dir.at[taker].set(0),
        ball_pos=jnp.concatenate([spot, jnp.zeros((1,))]),
        ball_vel=jnp.zeros((3,)),
        owner=taker,
        last_touch=taker,
        pass_receiver=jnp.int32(-1),
        game_mode=jnp.asarray(mode, jnp.int32),
        mode_timer=jnp.int32(0),
    )


def _kick(state: FootballState, actions: jax.Array, noise: Noise) -> tuple[FootballState, jax.Array]:
    """The carrier's pass or shot, if he asked for one. Returns (state, kicked)."""
    owner = jnp.maximum(state.owner, 0)
    act = actions[owner]
    is_kick = (act >= C.LONG_PASS) & (act <= C.SHOT)
    kicked = (state.owner >= 0) & is_kick & (state.stun[owner] == 0)
    target = physics.pass_target(state, owner)
    velocity = jnp.where(act == C.SHOT, physics.shot_velocity(state, owner, noise),
                         physics.pass_velocity(state, owner, target, act))
    after = state.replace(
        ball_vel=velocity,
        owner=jnp.int32(-1),
        last_touch=owner.astype(jnp.int32),
        pass_receiver=jnp.where(act == C.SHOT, -1, target).astype(jnp.int32),
        cooldown=state.cooldown.at[owner].set(C.KICK_COOLDOWN),
        game_mode=jnp.int32(C.NORMAL),
        mode_timer=jnp.int32(0),
    )
    return select_tree(kicked, after, state), kicked


def _tackles(state: FootballState, sliding_now: jax.Array, in_restart: jax.Array, noise: Noise):
    """Standing and sliding tackles on the carrier. Returns (state, foul)."""
    owner = jnp.maximum(state.owner, 0)
    carried = (state.owner >= 0) & ~in_restart
    opponent = jnp.asarray(_TEAM_OF) != player_team(owner)
    dist = norm2(state.pos - state.ball_pos[:2])
    able = (state.cooldown == 0) & ((state.stun == 0) | sliding_now)
    standing = carried & opponent & able & ~sliding_now & (dist < C.TACKLE_RADIUS)
    slider = carried & opponent & able & sliding_now & (dist < C.SLIDE_RADIUS)
    p_stand = C.STANDING_TACKLE_PROB * jnp.where(state.dribble[owner], C.DRIBBLE_TACKLE_FACTOR, 1.0)
    roll = noise.uniform[:, 1]
    success = (standing & (roll < p_stand)) | (slider & (roll < C.SLIDE_TACKLE_PROB))
    winner = jnp.argmin(jnp.where(success, dist, _INF)).astype(jnp.int32)
    won = jnp.any(success)
    foul = ~won & jnp.any(slider)
    after = state.replace(
        owner=winner, last_touch=winner, pass_receiver=jnp.int32(-1),
        cooldown=state.cooldown.at[owner].set(C.TACKLED_COOLDOWN),
    )
    return select_tree(won, after, state), foul


def _control(state: FootballState, prev_ball: jax.Array, noise: Noise) -> FootballState:
    """A loose ball is taken by the nearest player who reaches its path and controls it."""
    loose = state.owner < 0
    path_dist = physics.segment_distance(state.pos, prev_ball[:2], state.ball_pos[:2])
    low_z = jnp.minimum(prev_ball[2], state.ball_pos[2])
    keeper_hands = jnp.asarray(_IS_GK) & in_own_penalty_area(state.pos, jnp.asarray(_TEAM_OF))
    radius = jnp.where(keeper_hands, C.GK_CONTROL_RADIUS, C.CONTROL_RADIUS)
    height = jnp.where(keeper_hands, C.GK_CONTROL_HEIGHT, C.CONTROL_HEIGHT)
    speed = norm2(state.ball_vel[:2])
    p_control = jnp.where(keeper_hands, jnp.clip(1.3 - 12.0 * speed, 0.35, 1.0),
                          jnp.clip(1.4 - 16.0 * speed, 0.25, 1.0))
    able = (state.cooldown == 0) & (state.stun == 0)
    reach = loose & able & (path_dist < radius) & (low_z < height) & (noise.uniform[:, 0] < p_control)
    winner = jnp.argmin(jnp.where(reach, path_dist, _INF)).astype(jnp.int32)
    # A keeper who catches the ball gathers it facing the play: the controlled ball sits
    # BALL_OFFSET in front of its holder, so a keeper backing onto his line while
    # facing his own goal would otherwise hold it over the line (a goal he saved).
    keeper_catch = jnp.any(reach & keeper_hands & (jnp.asarray(_IDX) == winner))
    to_field = jnp.stack([team_sign(jnp.asarray(_TEAM_OF)[winner]), 0.0])
    facing = jnp.where(keeper_catch, state.facing.at[winner].set(to_field), state.facing)
    after = state.replace(
        owner=winner, last_touch=winner, pass_receiver=jnp.int32(-1),
        ball_vel=jnp.zeros((3,)), ball_pos=state.ball_pos.at[2].set(0.0), facing=facing,
    )
    return select_tree(jnp.any(reach), after, state)


def _attach_ball(state: FootballState) -> FootballState:
    owner = jnp.maximum(state.owner, 0)
    xy = state.pos[owner] + state.facing[owner] * C.BALL_OFFSET
    attached = state.replace(
        ball_pos=jnp.concatenate([xy, jnp.zeros((1,))]),
        ball_vel=jnp.concatenate([state.vel[owner], jnp.zeros((1,))]),
    )
    return select_tree(state.owner >= 0, attached, state)


def _out_of_play(state: FootballState, prev_ball: jax.Array, foul: jax.Array):
    """Goals and restarts after the ball moved. Returns (state, goals i32[2])."""
    bx, by, bz = state.ball_pos[0], state.ball_pos[1], state.ball_pos[2]
    px, py = prev_ball[0], prev_ball[1]
    crossed_right = bx > C.FIELD_X
    crossed_left = bx < -C.FIELD_X
    line_x = jnp.where(crossed_right, C.FIELD_X, -C.FIELD_X)
    t = jnp.clip((line_x - px) / (bx - px + jnp.where(bx >= px, 1e-9, -1e-9)), 0.0, 1.0)
    y_cross = py + t * (by - py)
    mouth = (jnp.abs(y_cross) < C.GOAL_HALF_WIDTH) & (bz < C.GOAL_HEIGHT)
    goal_left = crossed_right & mouth     # the left team scores in the right goal
    goal_right = crossed_left & mouth
    last_team = jnp.maximum(player_team(state.last_touch), 0)
    end_out = (crossed_right | crossed_left) & ~mouth
    defender = jnp.where(crossed_right, 1, 0)     # team defending the goal line crossed
    corner = end_out & (last_team == defender)
    side_out = (jnp.abs(by) > C.FIELD_Y) & ~crossed_right & ~crossed_left

    end_sign = jnp.where(crossed_right, 1.0, -1.0)
    side_sign = jnp.where(by >= 0, 1.0, -1.0)
    corner_spot = jnp.stack([end_sign * 0.995, side_sign * 0.415])
    goal_kick_spot = jnp.stack([end_sign * 0.9, 0.0])
    throw_spot = jnp.stack([jnp.clip(bx, -0.99, 0.99), side_sign * 0.415])
    foul_team = player_team(jnp.maximum(state.owner, 0))        # the fouled (carrying) team
    penalty = in_own_penalty_area(state.ball_pos[:2], 1 - foul_team)
    free_spot = jnp.clip(state.ball_pos[:2], jnp.array([-0.99, -0.41]), jnp.array([0.99, 0.41]))
    penalty_spot = jnp.stack([team_sign(foul_team) * C.PENALTY_SPOT_X, 0.0])

    mode = jnp.where(end_out, jnp.where(corner, C.CORNER, C.GOAL_KICK),
                     jnp.where(side_out, C.THROW_IN, jnp.where(penalty, C.PENALTY, C.FREE_KICK)))
    team = jnp.where(end_out, jnp.where(corner, 1 - defender, defender),
                     jnp.where(side_out, 1 - last_team, foul_team))
    spot = jnp.where(end_out, jnp.where(corner, corner_spot, goal_kick_spot),
                     jnp.where(side_out, throw_spot, jnp.where(penalty, penalty_spot, free_spot)))
    restart = end_out | side_out | (foul & ~goal_left & ~goal_right)
    state = select_tree(restart, apply_restart(state, mode, team, spot), state)

    scored = goal_left | goal_right
    goals = jnp.stack([goal_left, goal_right]).astype(jnp.int32)
    after_goal = kickoff(state.replace(score=state.score + goals), jnp.where(goal_left, 1, 0))
    return select_tree(scored, after_goal, state), goals


def step_game(state: FootballState, actions: jax.Array, noise: Noise) -> tuple[FootballState, jax.Array]:
    """Advance the match one tick given every player's action i32[22] (0..18).

    Returns the new state and goals i32[2] scored this tick by (left, right).
    """
    actions = jnp.asarray(actions, jnp.int32)
    in_restart = state.game_mode != C.NORMAL
    state = state.replace(stun=jnp.maximum(state.stun - 1, 0),
                          cooldown=jnp.maximum(state.cooldown - 1, 0))
    state = physics.apply_sticky(state, actions)
    state, kicked = _kick(state, actions, noise)
    in_restart = in_restart & ~kicked
    sliding_now = (actions == C.SLIDING) & (state.stun == 0) & (jnp.asarray(_IDX) != state.owner) & ~in_restart
    state = state.replace(stun=jnp.where(sliding_now, C.SLIDE_STUN, state.stun))
    frozen = in_restart & (jnp.asarray(_IDX) == state.owner)
    state = physics.move_players(state, sliding_now, frozen)

    prev_ball = state.ball_pos
    flown_pos, flown_vel = physics.ball_flight(state.ball_pos, state.ball_vel)
    loose = state.owner < 0
    state = state.replace(ball_pos=jnp.where(loose, flown_pos, state.ball_pos),
                          ball_vel=jnp.where(loose, flown_vel, state.ball_vel))
    state = _attach_ball(state)
    # During a restart the opponents are held away from the ball.
    held = _push_out(state.pos, state.ball_pos[:2], jnp.asarray(_TEAM_OF) != player_team(jnp.maximum(state.owner, 0)),
                     C.RESTART_CLEARANCE, jnp.zeros((2,)))
    state = state.replace(pos=jnp.where(in_restart & (state.owner >= 0), held, state.pos))
    state, foul = _tackles(state, sliding_now, in_restart, noise)
    state = _control(state, prev_ball, noise)
    state = _attach_ball(state)
    timer = state.mode_timer + in_restart.astype(jnp.int32)
    state = state.replace(
        mode_timer=timer,
        game_mode=jnp.where(in_restart & (timer >= C.RESTART_MAX_TICKS), C.NORMAL, state.game_mode),
    )
    return _out_of_play(state, prev_ball, foul)
