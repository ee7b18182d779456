"""Observations, always from the left (agent's) team's perspective.

"simple115" (GRF's compact vector, 115 floats):
  [0:22]    left positions, (x, y) per player 0..10, interleaved
  [22:44]   left directions (movement per step, dx, dy), interleaved
  [44:66]   right positions, interleaved
  [66:88]   right directions, interleaved
  [88:91]   ball position x, y, height
  [91:94]   ball direction (movement per step) dx, dy, dz
  [94:97]   ball owner team one-hot: (nobody, left, right)
  [97:108]  active player one-hot: the left carrier if we have the ball, else the left
            player nearest to it (the agent commands all 11; this marks the key one)
  [108:115] game mode one-hot (normal, kick-off, goal kick, free kick, corner,
            throw-in, penalty)

"paper" (the reference learner's 139 floats):
  [0:22]    left positions, interleaved      [22:44]   right positions, interleaved
  [44:66]   left directions, interleaved     [66:88]   right directions, interleaved
  [88:99]   left roles, role id / 9 (GK 0 ... CF 1)   [99:110]  right roles, same
  [110:113] ball position                    [113:116] ball direction
  [116:119] owner team one-hot (nobody, left, right)
  [119:130] owner player one-hot within his team (all zero if nobody owns the ball)
  [130:132] score (left, right)              [132:139] game mode one-hot
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.envs.football import constants as C
from smjax.envs.football.physics import norm2
from smjax.envs.football.types import FootballState, player_team

OBSERVATION_SIZES = {"simple115": 115, "paper": 139}
# numpy, so that importing runs no XLA program (see physics.DIRS)
_ROLES = C.ROLES.astype(np.float32) / np.float32(9.0)


def _owner_team_onehot(state: FootballState) -> jax.Array:
    return jax.nn.one_hot(player_team(state.owner) + 1, 3)


def active_player(state: FootballState) -> jax.Array:
    """The left player the observation marks: our carrier, else our nearest to the ball."""
    dist = norm2(state.pos[: C.NUM_PLAYERS] - state.ball_pos[:2])
    nearest = jnp.argmin(dist)
    return jnp.where((state.owner >= 0) & (state.owner < C.NUM_PLAYERS), state.owner, nearest)


def simple115(state: FootballState) -> jax.Array:
    n = C.NUM_PLAYERS
    parts = [
        state.pos[:n].reshape(-1), state.vel[:n].reshape(-1),
        state.pos[n:].reshape(-1), state.vel[n:].reshape(-1),
        state.ball_pos, state.ball_vel,
        _owner_team_onehot(state),
        jax.nn.one_hot(active_player(state), n),
        jax.nn.one_hot(state.game_mode, C.NUM_GAME_MODES),
    ]
    return jnp.concatenate(parts).astype(jnp.float32)


def paper139(state: FootballState) -> jax.Array:
    n = C.NUM_PLAYERS
    owner_in_team = jnp.where(state.owner >= 0, state.owner % n, -1)
    parts = [
        state.pos[:n].reshape(-1), state.pos[n:].reshape(-1),
        state.vel[:n].reshape(-1), state.vel[n:].reshape(-1),
        _ROLES, _ROLES,
        state.ball_pos, state.ball_vel,
        _owner_team_onehot(state),
        jax.nn.one_hot(owner_in_team, n),          # one_hot(-1) is all zeros
        state.score.astype(jnp.float32),
        jax.nn.one_hot(state.game_mode, C.NUM_GAME_MODES),
    ]
    return jnp.concatenate(parts).astype(jnp.float32)


def observe(state: FootballState, kind: str) -> jax.Array:
    if kind == "simple115":
        return simple115(state)
    if kind == "paper":
        return paper139(state)
    raise ValueError(f"unknown football observation {kind!r}; valid: {sorted(OBSERVATION_SIZES)}")
