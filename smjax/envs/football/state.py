"""Game state, params, per-tick random draws, kick-off setup and the mirror map.

``FootballState`` holds all 22 players as arrays (index ``11 * team + i``), the ball
(with height) and the match bookkeeping. ``Noise`` holds every random number a tick
uses, indexed by player, so that the whole tick is a deterministic function of
(state, actions, noise); mirroring a state and swapping the noise's team halves then
mirrors the tick exactly (the symmetry test relies on this).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from smjax.core.sampling import key_words
from smjax.envs.football import constants as C


@struct.dataclass
class FootballState:
    pos: jax.Array          # f32[22, 2]
    vel: jax.Array          # f32[22, 2] displacement per step
    facing: jax.Array       # f32[22, 2] unit vector
    sticky_dir: jax.Array   # i32[22] 0 = none, 1..8 = action direction
    sprint: jax.Array       # bool[22]
    dribble: jax.Array      # bool[22]
    stun: jax.Array         # i32[22] ticks left on the ground after a sliding tackle
    cooldown: jax.Array     # i32[22] ticks before the player may touch the ball again
    ai_prev: jax.Array      # i32[22] last built-in AI action (reaction delay keeps it)
    ball_pos: jax.Array     # f32[3] x, y, height
    ball_vel: jax.Array     # f32[3]
    owner: jax.Array        # i32 player controlling the ball, -1 = loose
    last_touch: jax.Array   # i32 player who touched the ball last, -1 = nobody yet
    pass_receiver: jax.Array  # i32 intended receiver of the ball in flight, -1 = none
    game_mode: jax.Array    # i32 constants.NORMAL .. PENALTY
    mode_timer: jax.Array   # i32 ticks spent in the current restart
    score: jax.Array        # i32[2] (left, right)
    step: jax.Array         # i32 ticks played this episode
    checkpoints: jax.Array  # i32 checkpoint rewards already paid (0..10)


@struct.dataclass
class FootballParams:
    """Traced parameters (vmap them for sweeps).

    difficulty: the opponent's built-in AI (easy 0.05, medium 0.6, hard 0.95).
    teammate_difficulty: the built-in AI that moves left players whose action is 19.
    checkpoint_reward: add GRF's checkpoint shaping to the scoring reward.
    """

    difficulty: jax.Array = struct.field(default_factory=lambda: jnp.float32(0.6))
    teammate_difficulty: jax.Array = struct.field(default_factory=lambda: jnp.float32(0.95))
    checkpoint_reward: jax.Array = struct.field(default_factory=lambda: jnp.bool_(False))


@struct.dataclass
class Noise:
    uniform: jax.Array  # f32[22, NUM_UNIFORM] in [0, 1)
    normal: jax.Array   # f32[22, NUM_NORMAL]


def _mix32(x: jax.Array) -> jax.Array:
    """A strong 32-bit integer mixer (the "lowbias32" finaliser)."""
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)




def draw_noise(key: jax.Array) -> Noise:
    """All of a tick's random numbers from one key.

    The key's words seed a counter-based generator (an integer hash of key and counter),
    which is far cheaper than drawing 300 numbers with threefry and matters because the
    whole step is only a few thousand operations. Keys given to ``step`` are already
    threefry outputs, so the hash only has to decorrelate the counters; each 32-bit hash
    gives two 16-bit uniforms (resolution 1/65536 is plenty for game events). Normal draws are
    triangular (sum of two uniforms, scaled to unit variance): the game only needs
    symmetric, bell-shaped noise.
    """
    words = key_words(key)
    seed_a = words[0]
    seed_b = words[-1] ^ jnp.uint32(0x9E3779B9) * jnp.uint32(words.shape[0])
    width = C.NUM_UNIFORM + 2 * C.NUM_NORMAL          # even: two 16-bit draws per hash
    counter = jnp.arange(C.NUM_TOTAL * width // 2, dtype=jnp.uint32)
    bits = _mix32((counter * jnp.uint32(0x9E3779B9) + seed_a) ^ seed_b)
    halves = jnp.stack([bits >> 16, bits & jnp.uint32(0xFFFF)], axis=-1)
    u = (halves.astype(jnp.float32) + 0.5) * jnp.float32(2.0**-16)
    u = u.reshape(C.NUM_TOTAL, width)
    pair = u[:, C.NUM_UNIFORM:].reshape(C.NUM_TOTAL, C.NUM_NORMAL, 2)
    normal = (pair[..., 0] + pair[..., 1] - 1.0) * jnp.float32(6.0**0.5)
    # Materialise the draws once: otherwise XLA re-computes the hash inside every
    # fusion that reads it (it counts integer ops as cheap), several times per tick.
    return jax.lax.optimization_barrier(Noise(uniform=u[:, : C.NUM_UNIFORM], normal=normal))


def team_sign(team) -> jax.Array:
    """+1 for the left team (attacks toward x = +1), -1 for the right team."""
    return 1.0 - 2.0 * jnp.asarray(team, jnp.float32)


def player_team(idx) -> jax.Array:
    """Team (0 left, 1 right) of player index; -1 for -1 (nobody)."""
    idx = jnp.asarray(idx)
    return jnp.where(idx < 0, -1, idx // C.NUM_PLAYERS)


def kickoff_positions(kicking_team) -> jax.Array:
    """f32[22, 2]: both teams in formation; the defending team's centre pair drops back."""
    form = jnp.asarray(C.FORMATION)
    back = form.at[1:3].set(jnp.asarray(C.KICKOFF_DEFENDER_SPOTS))
    left = jnp.where(kicking_team == 0, form, back)
    right = -jnp.where(kicking_team == 1, form, back)
    return jnp.concatenate([left, right], axis=0)


def kickoff(state: FootballState, kicking_team) -> FootballState:
    """Reset players and ball for a kick-off taken by ``kicking_team`` (score kept)."""
    sign = jnp.where(jnp.arange(C.NUM_TOTAL) < C.NUM_PLAYERS, 1.0, -1.0)
    facing = jnp.stack([sign, jnp.zeros_like(sign)], axis=1)
    taker = C.NUM_PLAYERS * kicking_team + 1
    # The taker stands just behind the ball on the centre spot, facing the other goal.
    pos = kickoff_positions(kicking_team).at[taker].set(-facing[taker] * C.BALL_OFFSET)
    zeros_i = jnp.zeros((C.NUM_TOTAL,), jnp.int32)
    zeros_b = jnp.zeros((C.NUM_TOTAL,), bool)
    return state.replace(
        pos=pos,
        vel=jnp.zeros_like(pos),
        facing=facing,
        sticky_dir=zeros_i,
        sprint=zeros_b,
        dribble=zeros_b,
        stun=zeros_i,
        cooldown=zeros_i,
        ball_pos=jnp.zeros((3,), jnp.float32),
        ball_vel=jnp.zeros((3,), jnp.float32),
        owner=jnp.asarray(taker, jnp.int32),
        last_touch=jnp.asarray(taker, jnp.int32),
        pass_receiver=jnp.int32(-1),
        game_mode=jnp.int32(C.KICK_OFF),
        mode_timer=jnp.int32(0),
    )


def initial_state(kicking_team: int = 0) -> FootballState:
    """A fresh match at 0-0, ``kicking_team`` to kick off."""
    n = C.NUM_TOTAL
    blank = FootballState(
        pos=jnp.zeros((n, 2)), vel=jnp.zeros((n, 2)), facing=jnp.zeros((n, 2)),
        sticky_dir=jnp.zeros((n,), jnp.int32), sprint=jnp.zeros((n,), bool),
        dribble=jnp.zeros((n,), bool), stun=jnp.zeros((n,), jnp.int32),
        cooldown=jnp.zeros((n,), jnp.int32), ai_prev=jnp.zeros((n,), jnp.int32),
        ball_pos=jnp.zeros((3,)), ball_vel=jnp.zeros((3,)), owner=jnp.int32(-1),
        last_touch=jnp.int32(-1), pass_receiver=jnp.int32(-1), game_mode=jnp.int32(0),
        mode_timer=jnp.int32(0), score=jnp.zeros((2,), jnp.int32), step=jnp.int32(0),
        checkpoints=jnp.int32(0),
    )
    return kickoff(blank, jnp.int32(kicking_team))


# ---- mirror map: reflect through the centre spot and swap the teams ----------------
def _swap_teams(x: jax.Array) -> jax.Array:
    return jnp.roll(x, C.NUM_PLAYERS, axis=0)


def _swap_index(idx: jax.Array) -> jax.Array:
    return jnp.where(idx < 0, idx, (idx + C.NUM_PLAYERS) % C.NUM_TOTAL)


def mirror_action(action: jax.Array) -> jax.Array:
    """The same action for the reflected pitch: directions turn by 180 degrees."""
    action = jnp.asarray(action)
    is_dir = (action >= 1) & (action <= 8)
    return jnp.where(is_dir, (action - 1 + 4) % 8 + 1, action)


def mirror_state(state: FootballState) -> FootballState:
    """The state seen with the pitch turned 180 degrees and the teams swapped."""
    return state.replace(
        pos=-_swap_teams(state.pos),
        vel=-_swap_teams(state.vel),
        facing=-_swap_teams(state.facing),
        sticky_dir=mirror_action(_swap_teams(state.sticky_dir)),
        sprint=_swap_teams(state.sprint),
        dribble=_swap_teams(state.dribble),
        stun=_swap_teams(state.stun),
        cooldown=_swap_teams(state.cooldown),
        ai_prev=mirror_action(_swap_teams(state.ai_prev)),
        ball_pos=state.ball_pos * jnp.array([-1.0, -1.0, 1.0]),
        ball_vel=state.ball_vel * jnp.array([-1.0, -1.0, 1.0]),
        owner=_swap_index(state.owner),
        last_touch=_swap_index(state.last_touch),
        pass_receiver=_swap_index(state.pass_receiver),
        score=state.score[::-1],
    )


def mirror_noise(noise: Noise) -> Noise:
    return Noise(uniform=_swap_teams(noise.uniform), normal=_swap_teams(noise.normal))


def mirror_actions(actions: jax.Array) -> jax.Array:
    """Per-player actions i32[22] for the mirrored state."""
    return mirror_action(_swap_teams(actions))
