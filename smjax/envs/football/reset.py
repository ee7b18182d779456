"""Episode starts and kick-offs: both teams in formation, the ball on the centre spot.

Every episode starts from the same state (0-0, the left team kicks off), so the
environment's reset ignores its key. ``kickoff`` is also the restart after a goal
(``rules``).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.football import constants as C
from smjax.envs.football.types import FootballState


def kickoff_positions(kicking_team) -> jax.Array:
    """f32[22, 2]: both teams in formation; the defending team's centre pair drops back."""
    form = jnp.asarray(C.FORMATION)
    back = form.at[1:3].set(jnp.asarray(C.KICKOFF_DEFENDER_SPOTS))
    left = jnp.where(kicking_team == 0, form, back)
    right = -jnp.where(kicking_team == 1, form, back)
    return jnp.concatenate([left, right], axis=0)


def kickoff(state: FootballState, kicking_team) -> FootballState:
    """Reset players and ball for a kick-off taken by ``kicking_team`` (score kept)."""
    # float32, not a Python float's weak type: a state whose types change between reset
    # and step would make a jitted step compile twice
    sign = jnp.where(jnp.arange(C.NUM_TOTAL) < C.NUM_PLAYERS, jnp.float32(1.0), jnp.float32(-1.0))
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
