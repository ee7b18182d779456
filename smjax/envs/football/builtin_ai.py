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
import numpy as np
from flax import struct

from smjax.envs.football import constants as C
from smjax.envs.football.physics import DIRS, dot2, min_axis, norm2, sum_axis
from smjax.envs.football.mirror import mirror_action
from smjax.envs.football.noise import draw_noise
from smjax.envs.football.types import FootballState, Noise, player_team, team_sign

# numpy (see physics.DIRS): taken with jnp.asarray where used
_DIRS8 = DIRS[1:]
_FORM = C.FORMATION
_IS_GK = np.arange(C.NUM_PLAYERS) == C.GOALKEEPER


_TAN_22_5 = 0.41421356


def quantize_direction(vec: jax.Array) -> jax.Array:
    """Action 1..8 whose direction is closest to each vector f32[..., 2] (RIGHT for 0).

    Sector arithmetic instead of an 8-way argmax: it is exactly odd (-v gives the
    opposite direction), which the mirror symmetry needs, and cheap under vmap.
    """
    x, y = vec[..., 0], vec[..., 1]
    ax, ay = jnp.abs(x), jnp.abs(y)
    sx = jnp.where(ax > _TAN_22_5 * ay, jnp.sign(x), 0.0).astype(jnp.int32)
    sy = jnp.where(ay > _TAN_22_5 * ax, jnp.sign(y), 0.0).astype(jnp.int32)
    # top row: 2 3 4, middle: 1 . 5, bottom row: 8 7 6 (y grows downward).
    action = jnp.where(sy < 0, 3 + sx, jnp.where(sy > 0, 7 - sx, 3 + 2 * sx))
    return jnp.where((sx == 0) & (sy == 0), C.RIGHT, action).astype(jnp.int32)


def lane_blockers(start: jax.Array, ends: jax.Array, opp: jax.Array, width: float) -> jax.Array:
    """For passes start -> ends[j]: how many opponents stand within ``width`` of the lane."""
    ab = ends - start                                             # [11, 2]
    ao = opp - start                                              # [11, 2]
    # Elementwise products, not matmuls: tiny batched dots are slow on CPU under vmap.
    proj = ab[:, None, 0] * ao[None, :, 0] + ab[:, None, 1] * ao[None, :, 1]
    t = jnp.clip(proj / (dot2(ab, ab)[:, None] + 1e-9), 0.0, 1.0)
    gap = start + t[..., None] * ab[:, None, :] - opp[None]       # [11 mates, 11 opp, 2]
    d2 = gap[..., 0] ** 2 + gap[..., 1] ** 2
    return jnp.sum((d2 < width * width) & (t > 0.05), axis=1)


@struct.dataclass
class TeamView:
    """What one team's AI reads, in that team's frame (attacking toward x = +1)."""

    team: jax.Array        # i32 0 left, 1 right
    own: jax.Array         # f32[11, 2]
    opp: jax.Array         # f32[11, 2]
    facing: jax.Array      # f32[11, 2]
    uniform: jax.Array     # f32[11, NUM_UNIFORM]
    normal: jax.Array      # f32[11, NUM_NORMAL]
    cur_dir: jax.Array     # i32[11] sticky direction, in the team frame
    cur_sprint: jax.Array  # bool[11]
    cur_dribble: jax.Array  # bool[11]
    prev: jax.Array        # i32[11] previous AI action, in the team frame


def team_view(state: FootballState, noise: Noise, team: int) -> TeamView:
    """The view of a static ``team`` (plain slicing: no gathers on the per-step path)."""
    n = C.NUM_PLAYERS
    mine, theirs = (slice(0, n), slice(n, 2 * n)) if team == 0 else (slice(n, 2 * n), slice(0, n))
    sign = 1.0 if team == 0 else -1.0
    turn = (lambda a: a) if team == 0 else mirror_action
    return TeamView(
        team=jnp.int32(team), own=state.pos[mine] * sign, opp=state.pos[theirs] * sign,
        facing=state.facing[mine] * sign, uniform=noise.uniform[mine], normal=noise.normal[mine],
        cur_dir=turn(state.sticky_dir[mine]), cur_sprint=state.sprint[mine],
        cur_dribble=state.dribble[mine], prev=turn(state.ai_prev[mine]),
    )


def team_actions(state: FootballState, team: jax.Array, difficulty: jax.Array, noise: Noise) -> jax.Array:
    """Actions i32[11] (0..18, absolute directions) of ``team``'s built-in AI."""
    views = [team_view(state, noise, t) for t in (0, 1)]
    view = jax.tree.map(lambda a, b: jnp.where(jnp.asarray(team) == 1, b, a), *views)
    return decide(state, view, difficulty, carrier_plan(state, view, difficulty))


def carrier_plan(state: FootballState, view: TeamView, difficulty: jax.Array) -> tuple:
    """What the carrier of ``view``'s team wants: (direction, sprint, kick, dribble).

    Only one team has a carrier, so ``all_actions`` evaluates this once per tick, in
    the carrier's team frame (the pairwise lane checks are the AI's dearest part).
    """
    d = jnp.clip(jnp.asarray(difficulty, jnp.float32), 0.0, 1.0)
    team = view.team
    own, opp, u, n = view.own, view.opp, view.uniform, view.normal
    carrier = jnp.where(player_team(state.owner) == team, state.owner - C.NUM_PLAYERS * team, -1)
    is_carrier = jnp.arange(C.NUM_PLAYERS) == carrier
    # One-hot picks instead of gathers: under vmap a gather per env costs more than
    # an 11-element masked sum.
    pick_c = jnp.where(carrier >= 0, is_carrier, jnp.arange(C.NUM_PLAYERS) == 0)
    me = sum_axis(jnp.where(pick_c[:, None], own, 0.0), 0)
    to_goal = jnp.array([1.0, 0.0]) - me
    dist_goal = norm2(to_goal)
    goal_unit = to_goal / (dist_goal + 1e-9)
    probe = me + 0.08 * jnp.asarray(_DIRS8)                                     # [8, 2]
    # Crowding of each probe point: a polynomial bump of radius 0.08 per opponent
    # (cheaper than a Gaussian and just as smooth where it matters).
    gap = probe[:, None] - opp[None]
    crowd = sum_axis(jnp.maximum(1.0 - (gap[..., 0] ** 2 + gap[..., 1] ** 2) / 0.08**2, 0.0) ** 2, 1)
    off_pitch = (jnp.abs(probe[:, 1]) > 0.39) | (probe[:, 0] > 0.97) | (probe[:, 0] < -0.97)
    dribble_score = (dot2(jnp.asarray(_DIRS8), goal_unit) - 1.5 * crowd - 2.0 * off_pitch
                     + n[:8, 2] * (1.0 - d) * 0.8)
    dribble_dir = (jnp.argmax(dribble_score) + 1).astype(jnp.int32)

    mate_delta = own - me
    mate_dist = norm2(mate_delta)
    blockers = lane_blockers(me, own, opp, 0.03)
    mark = own[:, None] - opp[None]
    openness = jnp.sqrt(min_axis(mark[..., 0] ** 2 + mark[..., 1] ** 2, 1))
    pass_score = (0.8 * mate_delta[:, 0] + 1.5 * jnp.minimum(openness, 0.12) - 0.5 * blockers
                  - 0.6 * jnp.maximum(mate_dist - 0.6, 0.0) - 0.3 * jnp.asarray(_IS_GK)
                  - 10.0 * is_carrier - 10.0 * (mate_dist < 0.08) + n[:, 1] * (1.0 - d) * 0.5)
    best_pass = -min_axis(-pass_score, 0)
    pick_m = jnp.arange(C.NUM_PLAYERS) == jnp.argmax(pass_score)
    opp_rel = opp - me
    opp_dist = norm2(opp_rel)
    ahead = dot2(opp_rel, goal_unit) > -0.01
    pressed = jnp.any((opp_dist < 0.06) & ahead) | jnp.any(opp_dist < 0.035)
    in_restart = state.game_mode != C.NORMAL
    u_c = sum_axis(jnp.where(pick_c[:, None], u, 0.0), 0)
    shoot_range = 0.28 + (1.0 - d) * 0.3 * u_c[5]
    shoot = (dist_goal < shoot_range) & (jnp.abs(me[1]) < 0.3)
    switch_play = (u_c[7] < 0.02) & (best_pass > 0.3)
    do_pass = ~shoot & ((pressed & (best_pass > -0.3)) | switch_play | in_restart)
    lane_blocked = jnp.any(pick_m & (blockers > 0))
    pass_dist = sum_axis(jnp.where(pick_m, mate_dist, 0.0), 0)
    pass_delta = sum_axis(jnp.where(pick_m[:, None], mate_delta, 0.0), 0)
    pass_kind = jnp.where(lane_blocked, C.HIGH_PASS,
                          jnp.where(pass_dist < 0.35, C.SHORT_PASS, C.LONG_PASS))
    carrier_kick = jnp.where(shoot, C.SHOT, jnp.where(do_pass, pass_kind, 0))
    carrier_dir = jnp.where(do_pass, quantize_direction(pass_delta), dribble_dir)
    carrier_sprint = ~jnp.any((opp_dist < 0.05) & ahead)
    return carrier_dir, carrier_sprint, carrier_kick, pressed


def decide(state: FootballState, view: TeamView, difficulty: jax.Array, plan: tuple) -> jax.Array:
    """The AI's actions i32[11] (absolute directions) for the team ``view`` describes.

    ``plan`` is ``carrier_plan`` for this team (ignored when it has no carrier).
    """
    d = jnp.clip(jnp.asarray(difficulty, jnp.float32), 0.0, 1.0)
    team = view.team
    sign = team_sign(team)
    u = view.uniform

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
    ball_ahead = loose_ball_target(state, ball, ball_vel)
    move_dir, want_sprint, slide = off_ball_moves(
        view, d, ball, ball_ahead, (we_have, they_have, loose), receiver)

    carrier_dir, carrier_sprint, carrier_kick, pressed = plan
    desired_dir = jnp.where(is_carrier, carrier_dir, move_dir)
    want_sprint = jnp.where(is_carrier, carrier_sprint, want_sprint)
    want_dribble = is_carrier & pressed
    kick = jnp.where(is_carrier, carrier_kick, jnp.where(slide, C.SLIDING, 0))

    # Low difficulty: now and then run a random way instead.
    wander = u[:, 3] < 0.15 * (1.0 - d)
    desired_dir = jnp.where(wander & ~is_carrier, 1 + jnp.floor(u[:, 4] * 8).astype(jnp.int32), desired_dir)

    action = sticky_action(view, kick, desired_dir, want_sprint, want_dribble)
    react = u[:, 2] < 0.15 + 0.85 * d
    action = jnp.where(react, action, view.prev).astype(jnp.int32)
    return jnp.where(team == 1, mirror_action(action), action)


def loose_ball_target(state: FootballState, ball: jax.Array, ball_vel: jax.Array) -> jax.Array:
    """Where a loose ball will be (team frame): its landing point if in the air, a little
    ahead if rolling."""
    vz, z = state.ball_vel[2], state.ball_pos[2]
    t_land = (vz + jnp.sqrt(vz * vz + 2.0 * C.GRAVITY * z)) / C.GRAVITY
    return ball + ball_vel * jnp.clip(jnp.where(z > 0.0, t_land, 4.0), 0.0, 20.0)


def off_ball_moves(view: TeamView, d: jax.Array, ball: jax.Array, ball_ahead: jax.Array,
                   possession: tuple, receiver: jax.Array) -> tuple:
    """Every player's run without the ball: formation anchors, pressing, receiving,
    goalkeeping. (direction 0..8, wants sprint, slides) per player, in the team frame;
    ``possession`` is (we have the ball, they have it, it is loose)."""
    we_have, they_have, loose = possession
    own, facing, u = view.own, view.facing, view.uniform
    # In possession the team stretches (forwards 0.25 ahead of the ball, wide wings);
    # without it the team sits compact between the ball and its own goal.
    attack_x = ball[0] * 0.6 + 0.25 + jnp.asarray(_FORM)[:, 0] * 0.7
    defend_x = ball[0] * 0.5 - 0.2 + jnp.asarray(_FORM)[:, 0] * 0.6
    attack_y = jnp.asarray(_FORM)[:, 1] * 1.6 + ball[1] * 0.2
    defend_y = jnp.asarray(_FORM)[:, 1] * 1.0 + ball[1] * 0.3
    anchor = jnp.stack([
        jnp.clip(jnp.where(we_have, attack_x, defend_x), -0.9, 0.85),
        jnp.clip(jnp.where(we_have, attack_y, defend_y), -0.38, 0.38),
    ], axis=1)
    gk_home = jnp.stack([-0.97, jnp.clip(ball[1] * 0.3, -0.035, 0.035)])
    anchor = anchor.at[C.GOALKEEPER].set(gk_home)
    d_ball = norm2(own - ball)
    d_field = jnp.where(jnp.asarray(_IS_GK), 1e9, d_ball)
    rank = jnp.sum(d_field[None, :] < d_field[:, None], axis=1)
    n_press = jnp.where(they_have, 1 + jnp.floor(2.99 * d), jnp.where(loose, 1.0, 0.0))
    chase = (rank < n_press) & ~jnp.asarray(_IS_GK)
    chase = chase | (jnp.arange(C.NUM_PLAYERS) == receiver)
    ball_near_goal = (ball[0] < -0.75) & (jnp.abs(ball[1]) < 0.22)
    chase = chase | (jnp.asarray(_IS_GK) & ~we_have & ball_near_goal & (d_ball < 0.15))
    chase_target = jnp.where(loose, ball_ahead, ball)
    target = jnp.where(chase[:, None], chase_target, anchor)
    to_target = target - own
    dist_target = norm2(to_target)
    move_dir = jnp.where(dist_target > 0.01, quantize_direction(to_target), 0)
    want_sprint = (dist_target > 0.08) | chase
    facing_ball = dot2(facing, ball - own) > 0.7 * d_ball
    slide = chase & they_have & (d_ball < 0.035) & facing_ball & (u[:, 6] < 0.08 * d)
    return move_dir, want_sprint, slide


def sticky_action(view: TeamView, kick: jax.Array, desired_dir: jax.Array,
                  want_sprint: jax.Array, want_dribble: jax.Array) -> jax.Array:
    """One action per player toward what he wants, honouring the sticky controls: a kick
    once aimed, else the first of direction, sprint and dribble that differs from the
    current one, else IDLE."""
    cur_dir = view.cur_dir
    aim_dir = jnp.where(cur_dir > 0, cur_dir, quantize_direction(view.facing))
    pass_ready = (kick >= C.LONG_PASS) & (kick <= C.SHORT_PASS) & (aim_dir == desired_dir)
    kick_ready = (kick == C.SHOT) | (kick == C.SLIDING) | pass_ready
    return jnp.where(
        (kick > 0) & kick_ready, kick,
        jnp.where(desired_dir != cur_dir, jnp.where(desired_dir > 0, desired_dir, C.RELEASE_DIRECTION),
                  jnp.where(want_sprint != view.cur_sprint,
                            jnp.where(want_sprint, C.SPRINT, C.RELEASE_SPRINT),
                            jnp.where(want_dribble != view.cur_dribble,
                                      jnp.where(want_dribble, C.DRIBBLE, C.RELEASE_DRIBBLE),
                                      C.IDLE))))


def all_actions(state: FootballState, difficulties: jax.Array, noise: Noise) -> jax.Array:
    """Built-in AI actions i32[22] for both teams; ``difficulties`` is f32[2] (left, right)."""
    views = jax.tree.map(lambda a, b: jnp.stack([a, b]), team_view(state, noise, 0),
                         team_view(state, noise, 1))
    difficulties = jnp.asarray(difficulties, jnp.float32)
    carrier_team = jnp.maximum(player_team(state.owner), 0)
    carrier_view = jax.tree.map(lambda v: v[carrier_team], views)
    plan = carrier_plan(state, carrier_view, difficulties[carrier_team])
    per_team = jax.vmap(decide, in_axes=(None, 0, 0, None))(state, views, difficulties, plan)
    return per_team.reshape(C.NUM_TOTAL)


def builtin_ai(key: jax.Array, state: FootballState, team: int | jax.Array, difficulty) -> jax.Array:
    """The built-in AI's actions i32[11] for ``team`` (0 left, 1 right) at ``difficulty``."""
    return team_actions(state, jnp.asarray(team, jnp.int32), difficulty, draw_noise(key))
