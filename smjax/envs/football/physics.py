"""Player motion, sticky actions, kicks (passes and shots) and ball flight.

Rules chosen (documented here because they shape play):

* Directions, sprint and dribble are sticky: action 1..8 sets the running direction
  until RELEASE_DIRECTION (14) or another direction; SPRINT/RELEASE_SPRINT and
  DRIBBLE/RELEASE_DRIBBLE toggle flags. IDLE changes nothing.
* A player accelerates toward ``direction * speed`` (run, sprint, dribble speed;
  carriers are 10 % slower) closing 35 % of the gap per step; he faces where he runs.
* Only the ball carrier can kick. A pass goes to the teammate best aligned with the
  carrier's running direction (his facing when he has none), preferring near ones:
  SHORT_PASS is a ground ball hit at 0.02 + 0.05 * distance per step (it rolls past a
  player who stands still), LONG_PASS a low lofted ball (apex 0.05) and HIGH_PASS a high one
  (apex 0.15, above CONTROL_HEIGHT for most of its flight, so it clears interceptors),
  both landing at the receiver (aimed at where he will be).
* A shot is aimed at the goal post side away from the goalkeeper; the aim's angular
  error has standard deviation 0.01 + 0.1 * distance-to-goal radians, so shots from
  close range are accurate and long shots often miss.
* A loose ball flies under gravity, bounces (keeping 45 % of vertical, 80 % of
  horizontal speed) and rolls with friction; a controlled ball sits in front of its
  carrier.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.football import constants as C
from smjax.envs.football.types import FootballState, Noise, player_team, team_sign

# numpy, not jax.numpy: importing the package runs no XLA program (``smjax list``
# and every refusal answer before any compile); each use takes it with jnp.asarray
DIRS = C.DIRECTION_VECTORS


# 2-vector helpers written out by component. A reduction over a trailing axis of size 2
# (jnp.linalg.norm, .sum(-1)) becomes a library-call fusion on XLA:CPU that costs far
# more than the two multiplies it replaces: written out, the step runs about twice as fast.
def dot2(a: jax.Array, b: jax.Array) -> jax.Array:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def norm2(v: jax.Array) -> jax.Array:
    return jnp.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])


def sum_axis(x: jax.Array, axis: int) -> jax.Array:
    """Sum over a short float axis, unrolled (same reason as ``dot2``)."""
    parts = jnp.moveaxis(x, axis, 0)
    total = parts[0]
    for i in range(1, parts.shape[0]):
        total = total + parts[i]
    return total


def min_axis(x: jax.Array, axis: int) -> jax.Array:
    """Minimum over a short float axis, unrolled."""
    parts = jnp.moveaxis(x, axis, 0)
    low = parts[0]
    for i in range(1, parts.shape[0]):
        low = jnp.minimum(low, parts[i])
    return low


def apply_sticky(state: FootballState, actions: jax.Array) -> FootballState:
    """Update sticky direction/sprint/dribble from per-player actions i32[22]."""
    down = state.stun > 0   # players on the ground ignore their controls
    is_dir = (actions >= C.LEFT) & (actions <= C.BOTTOM_LEFT)
    new_dir = jnp.where(is_dir, actions, jnp.where(actions == C.RELEASE_DIRECTION, 0, state.sticky_dir))
    sprint = jnp.where(actions == C.SPRINT, True, jnp.where(actions == C.RELEASE_SPRINT, False, state.sprint))
    dribble = jnp.where(actions == C.DRIBBLE, True,
                        jnp.where(actions == C.RELEASE_DRIBBLE, False, state.dribble))
    return state.replace(
        sticky_dir=jnp.where(down, state.sticky_dir, new_dir),
        sprint=jnp.where(down, state.sprint, sprint),
        dribble=jnp.where(down, state.dribble, dribble),
    )


def move_players(state: FootballState, sliding_now: jax.Array, frozen: jax.Array) -> FootballState:
    """Integrate player positions one step (sliding players lunge, frozen ones stand)."""
    idx = jnp.arange(C.NUM_TOTAL)
    is_carrier = idx == state.owner
    dir_vec = jnp.asarray(DIRS)[state.sticky_dir]
    speed = jnp.where(state.sprint, C.SPRINT_SPEED, C.RUN_SPEED)
    speed = jnp.where(state.dribble, C.DRIBBLE_SPEED, speed)
    speed = jnp.where(is_carrier, speed * C.CARRIER_SPEED_FACTOR, speed)
    desired = dir_vec * speed[:, None]
    vel = state.vel + (desired - state.vel) * C.ACCELERATION
    down = state.stun > 0
    vel = jnp.where(down[:, None], state.vel * 0.7, vel)           # sliding decelerates
    vel = jnp.where(sliding_now[:, None], state.facing * C.SLIDE_SPEED, vel)
    vel = jnp.where(frozen[:, None], 0.0, vel)
    bound = jnp.array([C.PLAYER_BOUND_X, C.PLAYER_BOUND_Y])
    pos = jnp.clip(state.pos + vel, -bound, bound)
    moving = (state.sticky_dir > 0) & ~down
    facing = jnp.where(moving[:, None], dir_vec, state.facing)
    return state.replace(pos=pos, vel=vel, facing=facing)


def aim_direction(state: FootballState, player: jax.Array) -> jax.Array:
    """Unit vector a player aims along: his sticky direction, else his facing."""
    sticky = jnp.asarray(DIRS)[state.sticky_dir[player]]
    has_dir = state.sticky_dir[player] > 0
    return jnp.where(has_dir, sticky, state.facing[player])


def pass_target(state: FootballState, kicker: jax.Array) -> jax.Array:
    """Teammate (global index) a pass by ``kicker`` goes to: best aligned, then nearest."""
    team = player_team(kicker)
    aim = aim_direction(state, kicker)
    mates = jnp.arange(C.NUM_PLAYERS) + C.NUM_PLAYERS * team
    delta = state.pos[mates] - state.pos[kicker]
    dist = norm2(delta) + 1e-6
    cos = dot2(delta, aim) / dist
    # Within 60 degrees of the aim a near teammate beats a far one; outside it only as
    # a last resort (then the best aligned of all).
    score = cos - 0.4 * dist - 10.0 * (cos < 0.5) - 100.0 * (mates == kicker)
    return mates[jnp.argmax(score)]


def _lofted_velocity(delta: jax.Array, apex: float) -> jax.Array:
    """Initial velocity of a ball that peaks at ``apex`` and lands ``delta`` away."""
    vz = jnp.sqrt(2.0 * C.GRAVITY * apex)
    flight = 2.0 * vz / C.GRAVITY
    vxy = delta / flight
    speed = norm2(vxy)
    vxy = vxy * jnp.minimum(1.0, C.MAX_KICK_SPEED / (speed + 1e-9))
    return jnp.concatenate([vxy, vz[None]])


def pass_velocity(state: FootballState, kicker: jax.Array, target: jax.Array, kind: jax.Array) -> jax.Array:
    """Ball velocity f32[3] for a pass of ``kind`` (LONG/HIGH/SHORT_PASS) to ``target``."""
    ball = state.ball_pos[:2]
    rough = norm2(state.pos[target] - ball)
    # Lead the receiver by roughly the time the ball needs to reach him.
    lead_time = jnp.clip(rough / 0.03, 0.0, 25.0)
    aim_point = state.pos[target] + state.vel[target] * lead_time
    delta = aim_point - ball
    dist = norm2(delta)
    unit = delta / (dist + 1e-9)
    # Rolls (base + gain d) / friction >= d, so a ground pass reaches a still receiver.
    ground_speed = jnp.minimum(C.PASS_BASE_SPEED + C.PASS_SPEED_GAIN * dist, C.MAX_KICK_SPEED)
    ground = jnp.concatenate([unit * ground_speed, jnp.zeros((1,))])
    long_ball = _lofted_velocity(delta * 0.9, C.LONG_PASS_APEX)
    high_ball = _lofted_velocity(delta, C.HIGH_PASS_APEX)
    return jnp.where(kind == C.SHORT_PASS, ground, jnp.where(kind == C.LONG_PASS, long_ball, high_ball))


def shot_velocity(state: FootballState, kicker: jax.Array, noise: Noise) -> jax.Array:
    """Ball velocity f32[3] of a shot by ``kicker`` at the opponents' goal."""
    team = player_team(kicker)
    sign = team_sign(team)
    keeper = C.NUM_PLAYERS * (1 - team) + C.GOALKEEPER
    ball = state.ball_pos[:2]
    # Aim inside the far post, away from the side the goalkeeper covers (tanh keeps the
    # choice odd in y, so a mirrored shot is aimed at the mirrored spot).
    gk_side = jnp.tanh(50.0 * ball[1] + 200.0 * state.pos[keeper, 1])
    aim = jnp.stack([sign * C.FIELD_X, -gk_side * C.GOAL_HALF_WIDTH * 0.6])
    delta = aim - ball
    dist = norm2(delta)
    angle = noise.normal[kicker, 0] * (0.01 + 0.1 * dist)
    c, s = jnp.cos(angle), jnp.sin(angle)
    unit = delta / (dist + 1e-9)
    rotated = jnp.stack([c * unit[0] - s * unit[1], s * unit[0] + c * unit[1]])
    return jnp.concatenate([rotated * C.SHOT_SPEED, jnp.array([C.SHOT_LIFT])])


def ball_flight(ball_pos: jax.Array, ball_vel: jax.Array) -> tuple[jax.Array, jax.Array]:
    """One step of a loose ball: gravity, bounce, drag in the air, friction on the ground."""
    vz = ball_vel[2] - jnp.where(ball_pos[2] > 0.0, C.GRAVITY, 0.0)
    pos = ball_pos + jnp.concatenate([ball_vel[:2], vz[None]])
    hit_ground = pos[2] <= 0.0
    bounce_vz = jnp.where(-vz * C.BOUNCE > 0.004, -vz * C.BOUNCE, 0.0)
    vz = jnp.where(hit_ground, bounce_vz, vz)
    # A ball that lands loses horizontal speed; a rolling ball slows by friction.
    on_ground = hit_ground & (bounce_vz == 0.0)
    vxy = jnp.where(hit_ground & (ball_pos[2] > 0.0), ball_vel[:2] * C.BOUNCE_SPEED_KEPT, ball_vel[:2])
    vxy = jnp.where(on_ground, vxy * (1.0 - C.GROUND_FRICTION), vxy * (1.0 - C.AIR_DRAG))
    vxy = jnp.where(norm2(vxy) < 1e-4, 0.0, vxy)
    pos = pos.at[2].set(jnp.maximum(pos[2], 0.0))
    return pos, jnp.concatenate([vxy, vz[None]])


def segment_distance(points: jax.Array, a: jax.Array, b: jax.Array) -> jax.Array:
    """Distance from each point f32[N, 2] to the segment a-b (the ball's path this step)."""
    ab = b - a
    t = jnp.clip(dot2(points - a, ab) / (dot2(ab, ab) + 1e-12), 0.0, 1.0)
    closest = a + t[:, None] * ab
    return norm2(points - closest)
