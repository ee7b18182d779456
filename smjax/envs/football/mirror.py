"""The mirror map: reflect the pitch through the centre spot and swap the teams.

The built-in AI plays the right team as the left team's AI on the mirrored state, and the
symmetry tests check that a mirrored tick is the tick of the mirrored state.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.football import constants as C
from smjax.envs.football.types import FootballState, Noise


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
