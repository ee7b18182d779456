"""Football's state, params and per-tick random draws (structs), and index helpers.

``FootballState`` holds all 22 players as arrays (index ``11 * team + i``), the ball
(with height) and the match bookkeeping. ``Noise`` holds every random number a tick
uses, indexed by player (drawn by ``noise.draw_noise``), so that the whole tick is a
deterministic function of (state, actions, noise); mirroring a state and swapping the
noise's team halves then mirrors the tick exactly (``mirror``; the symmetry test relies
on this).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

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
    max_steps: ticks before an episode is truncated (GRF's game length). Named and traced
    as every smjax environment's episode cap is, so the contract harness can shorten
    episodes and gymnax trainers read their evaluation length from it.
    """

    difficulty: jax.Array = struct.field(default_factory=lambda: jnp.float32(0.6))
    teammate_difficulty: jax.Array = struct.field(default_factory=lambda: jnp.float32(0.95))
    checkpoint_reward: jax.Array = struct.field(default_factory=lambda: jnp.bool_(False))
    max_steps: jax.Array = struct.field(default_factory=lambda: jnp.int32(3000))


@struct.dataclass
class Noise:
    uniform: jax.Array  # f32[22, NUM_UNIFORM] in [0, 1)
    normal: jax.Array   # f32[22, NUM_NORMAL]


def team_sign(team) -> jax.Array:
    """+1 for the left team (attacks toward x = +1), -1 for the right team."""
    return 1.0 - 2.0 * jnp.asarray(team, jnp.float32)


def player_team(idx) -> jax.Array:
    """Team (0 left, 1 right) of player index; -1 for -1 (nobody)."""
    idx = jnp.asarray(idx)
    return jnp.where(idx < 0, -1, idx // C.NUM_PLAYERS)
