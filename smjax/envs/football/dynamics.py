"""The environment's transition and reward: the agent's 11 actions, the built-in AI, one
game tick (``rules.step_game``), the scoring reward, checkpoint shaping and truncation.

Reward: +1 when the left team scores, -1 when it concedes; with
``params.checkpoint_reward`` also the checkpoint shaping (0.1 for each of 10 distance
thresholds 0.99 - 0.8 k / 9 to (1, 0) first reached with the ball under left control,
each paid once per episode; a goal pays the unpaid ones). Episodes never terminate;
they are truncated after ``params.max_steps`` ticks.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.football import constants as C
from smjax.envs.football.builtin_ai import all_actions
from smjax.envs.football.noise import draw_noise
from smjax.envs.football.physics import norm2
from smjax.envs.football.rules import step_game
from smjax.envs.football.types import FootballParams, FootballState


def step(key: jax.Array, state: FootballState, action: jax.Array, params: FootballParams):
    """(next state, reward f32, terminated bool, truncated bool, info) of one tick.

    ``action`` i32[11], one per left player: 0..18 the game's actions, 19 = the built-in
    AI (at ``params.teammate_difficulty``) moves that player; the right team is the
    built-in AI at ``params.difficulty``. info: ``score`` i32[2] (left, right),
    ``goal_difference`` (left - right), ``goals`` scored this tick i32[2].
    """
    action = jnp.clip(jnp.asarray(action, jnp.int32).reshape(C.NUM_PLAYERS), 0, C.BUILTIN_AI)
    noise = draw_noise(key)
    ai = all_actions(state, jnp.stack([params.teammate_difficulty, params.difficulty]), noise)
    left = jnp.where(action == C.BUILTIN_AI, ai[: C.NUM_PLAYERS], action)
    actions = jnp.concatenate([left, ai[C.NUM_PLAYERS:]])
    new, goals = step_game(state.replace(ai_prev=ai), actions, noise)
    new = new.replace(step=state.step + 1)

    # Checkpoint shaping: thresholds reached while the left team holds the ball.
    dist = norm2(new.ball_pos[:2] - jnp.array([1.0, 0.0]))
    reached = jnp.sum(dist < jnp.asarray(C.CHECKPOINT_THRESHOLDS)).astype(jnp.int32)
    left_has = (new.owner >= 0) & (new.owner < C.NUM_PLAYERS)
    paid = jnp.where(left_has, jnp.maximum(state.checkpoints, reached), state.checkpoints)
    paid = jnp.where(goals[0] > 0, C.NUM_CHECKPOINTS, paid)
    new = new.replace(checkpoints=paid)
    shaping = C.CHECKPOINT_REWARD * (paid - state.checkpoints).astype(jnp.float32)

    reward = (goals[0] - goals[1]).astype(jnp.float32)
    reward = reward + jnp.where(params.checkpoint_reward, shaping, 0.0)
    truncated = new.step >= params.max_steps
    info = {
        "score": new.score,
        "goal_difference": new.score[0] - new.score[1],
        "goals": goals,
    }
    return new, reward, jnp.bool_(False), truncated, info
