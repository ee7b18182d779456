"""AI-vs-AI matches: the built-in AI on both sides, one ``lax.scan`` per match."""
from __future__ import annotations

import jax

from smjax.envs.football.builtin_ai import all_actions
from smjax.envs.football.rules import step_game
from smjax.envs.football.noise import draw_noise
from smjax.envs.football.reset import initial_state
from smjax.envs.football.types import FootballState


def ai_tick(key: jax.Array, state: FootballState, difficulties: jax.Array) -> tuple[FootballState, jax.Array]:
    """One tick with the built-in AI playing both teams. Returns (state, goals i32[2])."""
    noise = draw_noise(key)
    actions = all_actions(state, difficulties, noise)
    state = state.replace(ai_prev=actions)
    state, goals = step_game(state, actions, noise)
    return state.replace(step=state.step + 1), goals


def play_match(key: jax.Array, difficulties: jax.Array, num_steps: int) -> jax.Array:
    """Final score i32[2] (left, right) of a match of ``num_steps`` ticks.

    ``difficulties`` f32[2] is (left AI, right AI). The left team kicks off. Jit with
    ``num_steps`` static; vmap over keys/difficulties for many games.
    """
    def body(state, k):
        state, _ = ai_tick(k, state, difficulties)
        return state, None

    final, _ = jax.lax.scan(body, initial_state(0), jax.random.split(key, num_steps))
    return final.score
