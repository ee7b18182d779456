"""The built-in AI: one pure function that plays a whole team, either side.

It works in the team's own frame (attacking toward x = +1; the right team's view is
the pitch turned 180 degrees), so both teams run the very same code and an AI-vs-AI
match is symmetric. It emits ordinary actions 0..18 one per player per tick, so it
lives with the same sticky controls as the agent: to pass it first turns toward the
receiver, then kicks; to sprint it first sets a direction, then toggles sprint.

Behaviour: the carrier shoots inside a shooting range, passes when pressed (to the
teammate with the best mix of progress, space and few opponents near the passing
lane; high pass over interceptors, long pass beyond 0.35) and otherwise dribbles in
the free direction that gains most ground. Without the ball the nearest players
press, the intended receiver runs to the ball, the goalkeeper guards the line and
comes out for balls near him, and everyone else keeps a formation shifted with the
ball.

``difficulty`` in [0, 1] (easy 0.05, medium 0.6, hard 0.95) changes three things:
* reaction: each player re-decides with probability 0.15 + 0.85 d per tick, else he
  repeats his previous action, and with probability 0.15 (1 - d) he runs a random way;
* decision quality: noise of scale (1 - d) on pass, dribble and shot choices, and the
  shooting range grows with that noise (easy teams shoot from afar);
* pressing: 1 + floor(2.99 d) players close down an opponent carrier (1, 2 or 3), and
  only keen teams slide in.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.football import constants as C
from smjax.envs.football.physics import DIRS
from smjax.envs.football.state import FootballState, Noise, draw_noise, mirror_action, player_team, team_sign

_DIRS8 = DIRS[1:]
_FORM = jnp.asarray(C.FORMATION)
_IS_GK = jnp.arange(C.NUM_PLAYERS) == C.GOALKEEPER


def quantize_direction(vec: jax.Array) -> jax.Array:
    """Action 1..8 whose direction is closest to each vector f32[..., 2]."""
    return (jnp.argmax(vec @ _DIRS8.T, axis=-1) + 1).astype(jnp.int32)


def _lane_blockers(start: jax.Array, ends: jax.Array, opp: jax.Array, width: float) -> jax.Array:
    """For passes start -> ends[j]: how many opponents stand within ``width`` of the lane."""
    ab = ends - start                                             # [11, 2]
    ao = opp - start                                              # [11, 2]
    t = jnp.clip((ab @ ao.T) / (jnp.sum(ab * ab, axis=1, keepdims=True) + 1e-9), 0.0, 1.0)
    closest = start + t[..., None] * ab[:, None, :]               # [11 mates, 11 opp, 2]
    d = jnp.linalg.norm(closest - opp[None], axis=-1)
    return jnp.sum((d < width) & (t > 0.05), axis=1)


def team_actions(state: FootballState, team: jax.Array, difficulty: jax.Array, noise: Noise) -> jax.Array:
    """Actions i32[11] (0..18, absolute directions) of ``team``'s built-in AI."""
    d = jnp.clip(jnp.asarray(difficulty, jnp.float32), 0.0, 1.0)
    sign = team_sign(team)
    own = state.pos.reshape(2, C.NUM_PLAYERS, 2)[team] * sign
    opp = state.pos.reshape(2, C.NUM_PLAYERS, 2)[1 - team] * sign
    facing = state.facing.reshape(2, C.NUM_PLAYERS, 2)[team] * sign
    u = noise.uniform.reshape(2, C.NUM_PLAYERS, C.NUM_UNIFORM)[team]
    n = noise.normal.reshape(2, C.NUM_PLAYERS, C.NUM_NORMAL)[team]
    cur_dir = state.sticky_dir.reshape(2, C.NUM_PLAYERS)[team]
    cur_dir = jnp.where(team == 1, mirror_action(cur_dir), cur_dir)
    cur_sprint = state.sprint.reshape(2, C.NUM_PLAYERS)[team]
    cur_dribble = state.dribble.reshape(2, C.NUM_PLAYERS)[team]
    prev = state.ai_prev.reshape(2, C.NUM_PLAYERS)[team]
    prev = jnp.where(team == 1, mirror_action(prev), prev)

    ball = state.ball_pos[:2] * sign
    ball_vel = state.ball_vel[:2] * sign
    owner_team = player_team(state.owner)
    we_have = owner_team == team
    they_have = owner_team == 1 - team
    loose = state.owner < 0
    carrier = jnp.where(we_have, state.owner - C.NUM_PLAYERS * team, -1)
    is_carrier = jnp.arange(C.NUM_PLAYERS) == carrier
    receiver = jnp.where(player_team(state.pass_receiver) == team,
                         state.pass_receiver - C.NUM_PLAYERS * team, -1)

    # Where a loose ball will be: its landing point if in the air, a little ahead if rolling.
    vz, z = state.ball_vel[2], state.ball_pos[2]
    t_land = (vz + jnp.sqrt(vz * vz + 2.0 * C.GRAVITY * z)) / C.GRAVITY
    ball_ahead = ball + ball_vel * jnp.clip(jnp.where(z > 0.0, t_land, 4.0), 0.0, 20.0)

    # ---- off the ball: formation anchors, pressing, receiving, goalkeeping ----------
    # In possession the team stretches (forwards 0.25 ahead of the ball, wide wings);
    # without it the team sits compact between the ball and its own goal.
    attack_x = ball[0] * 0.6 + 0.25 + _FORM[:, 0] * 0.7
    defend_x = ball[0] * 0.5 - 0.2 + _FORM[:, 0] * 0.6
    attack_y = _FORM[:, 1] * 1.6 + ball[1] * 0.2
    defend_y = _FORM[:, 1] * 1.0 + ball[1] * 0.3
    anchor = jnp.stack([
        jnp.clip(jnp.where(we_have, attack_x, defend_x), -0.9, 0.85),
        jnp.clip(jnp.where(we_have, attack_y, defend_y), -0.38, 0.38),
    ], axis=1)
    gk_home = jnp.stack([-0.97, jnp.clip(ball[1] * 0.3, -0.035, 0.035)])
    anchor = anchor.at[C.GOALKEEPER].set(gk_home)
    d_ball = jnp.linalg.norm(own - ball, axis=1)
    d_field = jnp.where(_IS_GK, 1e9, d_ball)
    rank = jnp.sum(d_field[None, :] < d_field[:, None], axis=1)
    n_press = jnp.where(they_have, 1 + jnp.floor(2.99 * d), jnp.where(loose, 1.0, 0.0))
    chase = (rank < n_press) & ~_IS_GK
    chase = chase | (jnp.arange(C.NUM_PLAYERS) == receiver)
    ball_near_goal = (ball[0] < -0.75) & (jnp.abs(ball[1]) < 0.22)
    chase = chase | (_IS_GK & ~we_have & ball_near_goal & (d_ball < 0.15))
    chase_target = jnp.where(loose, ball_ahead, ball)
    target = jnp.where(chase[:, None], chase_target, anchor)
    to_target = target - own
    dist_target = jnp.linalg.norm(to_target, axis=1)
    move_dir = jnp.where(dist_target > 0.01, quantize_direction(to_target), 0)
    want_sprint = (dist_target > 0.08) | chase
    facing_ball = jnp.sum(facing * (ball - own), axis=1) > 0.7 * d_ball
    slide = chase & they_have & (d_ball < 0.035) & facing_ball & (u[:, 6] < 0.08 * d)

    # ---- the carrier: shoot, pass or dribble --------------------------------------
    c = jnp.maximum(carrier, 0)
    me = own[c]
    to_goal = jnp.array([1.0, 0.0]) - me
    dist_goal = jnp.linalg.norm(to_goal)
    goal_unit = to_goal / (dist_goal + 1e-9)
    probe = me + 0.08 * _DIRS8                                     # [8, 2]
    crowd = jnp.sum(jnp.exp(-jnp.sum((probe[:, None] - opp[None]) ** 2, -1) / (2 * 0.04**2)), 1)
    off_pitch = (jnp.abs(probe[:, 1]) > 0.39) | (probe[:, 0] > 0.97) | (probe[:, 0] < -0.97)
    dribble_score = (_DIRS8 @ goal_unit - 1.5 * crowd - 2.0 * off_pitch
                     + n[:8, 2] * (1.0 - d) * 0.8)
    dribble_dir = (jnp.argmax(dribble_score) + 1).astype(jnp.int32)

    mate_delta = own - me
    mate_dist = jnp.linalg.norm(mate_delta, axis=1)
    blockers = _lane_blockers(me, own, opp, 0.03)
    openness = jnp.min(jnp.linalg.norm(own[:, None] - opp[None], axis=-1), axis=1)
    pass_score = (0.8 * mate_delta[:, 0] + 1.5 * jnp.minimum(openness, 0.12) - 0.5 * blockers
                  - 0.6 * jnp.maximum(mate_dist - 0.6, 0.0) - 0.3 * _IS_GK
                  - 10.0 * is_carrier - 10.0 * (mate_dist < 0.08) + n[:, 1] * (1.0 - d) * 0.5)
    mate = jnp.argmax(pass_score)
    opp_rel = opp - me
    opp_dist = jnp.linalg.norm(opp_rel, axis=1)
    ahead = opp_rel @ goal_unit > -0.01
    pressed = jnp.any((opp_dist < 0.06) & ahead) | jnp.any(opp_dist < 0.035)
    in_restart = state.game_mode != C.NORMAL
    shoot_range = 0.28 + (1.0 - d) * 0.3 * u[c, 5]
    shoot = (dist_goal < shoot_range) & (jnp.abs(me[1]) < 0.3)
    switch_play = (u[c, 7] < 0.02) & (pass_score[mate] > 0.3)
    do_pass = ~shoot & ((pressed & (pass_score[mate] > -0.3)) | switch_play | in_restart)
    pass_kind = jnp.where(blockers[mate] > 0, C.HIGH_PASS,
                          jnp.where(mate_dist[mate] < 0.35, C.SHORT_PASS, C.LONG_PASS))
    carrier_kick = jnp.where(shoot, C.SHOT, jnp.where(do_pass, pass_kind, 0))
    carrier_dir = jnp.where(do_pass, quantize_direction(mate_delta[mate]), dribble_dir)
    carrier_sprint = ~jnp.any((opp_dist < 0.05) & ahead)

    desired_dir = jnp.where(is_carrier, carrier_dir, move_dir)
    want_sprint = jnp.where(is_carrier, carrier_sprint, want_sprint)
    want_dribble = is_carrier & pressed
    kick = jnp.where(is_carrier, carrier_kick, jnp.where(slide, C.SLIDING, 0))

    # Low difficulty: now and then run a random way instead.
    wander = u[:, 3] < 0.15 * (1.0 - d)
    desired_dir = jnp.where(wander & ~is_carrier, 1 + jnp.floor(u[:, 4] * 8).astype(jnp.int32), desired_dir)

    # ---- one action per player, honouring the sticky controls ------------------------
    aim_dir = jnp.where(cur_dir > 0, cur_dir, quantize_direction(facing))
    pass_ready = (kick >= C.LONG_PASS) & (kick <= C.SHORT_PASS) & (aim_dir == desired_dir)
    kick_ready = (kick == C.SHOT) | (kick == C.SLIDING) | pass_ready
    action = jnp.where(
        (kick > 0) & kick_ready, kick,
        jnp.where(desired_dir != cur_dir, jnp.where(desired_dir > 0, desired_dir, C.RELEASE_DIRECTION),
                  jnp.where(want_sprint != cur_sprint, jnp.where(want_sprint, C.SPRINT, C.RELEASE_SPRINT),
                            jnp.where(want_dribble != cur_dribble,
                                      jnp.where(want_dribble, C.DRIBBLE, C.RELEASE_DRIBBLE), C.IDLE))))
    react = u[:, 2] < 0.15 + 0.85 * d
    action = jnp.where(react, action, prev).astype(jnp.int32)
    return jnp.where(team == 1, mirror_action(action), action)


def all_actions(state: FootballState, difficulties: jax.Array, noise: Noise) -> jax.Array:
    """Built-in AI actions i32[22] for both teams; ``difficulties`` is f32[2] (left, right)."""
    per_team = jax.vmap(team_actions, in_axes=(None, 0, 0, None))(
        state, jnp.arange(2), jnp.asarray(difficulties, jnp.float32), noise)
    return per_team.reshape(C.NUM_TOTAL)


def builtin_ai(key: jax.Array, state: FootballState, team: int | jax.Array, difficulty) -> jax.Array:
    """The built-in AI's actions i32[11] for ``team`` (0 left, 1 right) at ``difficulty``."""
    return team_actions(state, jnp.asarray(team, jnp.int32), difficulty, draw_noise(key))
