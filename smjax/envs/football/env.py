"""``FootballEnv``: 11 vs 11 football, the agent commands the whole left team.

Action: i32[11], one per left player: 0..18 the GRF actions (constants.ACTION_NAMES),
19 = let the built-in AI (at ``params.teammate_difficulty``) move that player. The
right team is always the built-in AI at ``params.difficulty``.

Reward: +1 when the left team scores, -1 when it concedes; with
``params.checkpoint_reward`` also GRF's checkpoint shaping (0.1 for each of 10
distance thresholds 0.99 - 0.8 k / 9 to (1, 0) first reached with the ball under left
control, each paid once per episode; a goal pays the unpaid ones). Episodes never
terminate; they are truncated after ``game_length`` ticks.
info: ``score`` i32[2] (left, right), ``goal_difference`` (left - right), ``goals``
scored this tick i32[2].
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.core import spaces
from smjax.core.overrides import INT32_MAX, parse_bool, parse_choice, parse_float, parse_int
from smjax.core.env import Environment, select_tree
from smjax.envs.football import constants as C
from smjax.envs.football.builtin_ai import all_actions
from smjax.envs.football.physics import norm2
from smjax.envs.football.observation import OBSERVATION_SIZES, observe
from smjax.envs.football.rules import step_game
from smjax.envs.football.state import FootballParams, FootballState, draw_noise, initial_state

DIFFICULTIES = {"easy": 0.05, "medium": 0.6, "hard": 0.95}


class FootballEnv(Environment[FootballState, FootballParams]):
    """11 vs 11 football in jax.numpy (static: observation kind and game length)."""

    def __init__(self, observation: str = "simple115", game_length: int = 3000,
                 difficulty: float = 0.6, checkpoint_reward: bool = False):
        self.observation = parse_choice("football observation", observation,
                                        sorted(OBSERVATION_SIZES))
        # strict: bool("False") is True and int(2.9) is 2; both would pass silently
        self.game_length = parse_int("game_length", game_length, 1, INT32_MAX)
        self._difficulty = parse_float("difficulty (easy 0.05, medium 0.6, hard 0.95)",
                                       difficulty, 0.0, 1.0)
        self._checkpoint_reward = parse_bool("checkpoint_reward", checkpoint_reward)

    @property
    def default_params(self) -> FootballParams:
        return FootballParams(difficulty=jnp.float32(self._difficulty),
                              teammate_difficulty=jnp.float32(0.95),
                              checkpoint_reward=jnp.bool_(self._checkpoint_reward))

    def get_obs(self, state: FootballState, params: FootballParams | None = None) -> jax.Array:
        return observe(state, self.observation)

    def reset_env(self, key: jax.Array, params: FootballParams) -> tuple[jax.Array, FootballState]:
        state = initial_state(0)   # the left team kicks off; the start is deterministic
        return self.get_obs(state, params), state

    def step_env(self, key: jax.Array, state: FootballState, action: jax.Array, params: FootballParams):
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
        truncated = new.step >= self.game_length
        info = {
            "score": new.score,
            "goal_difference": new.score[0] - new.score[1],
            "goals": goals,
        }
        return self.get_obs(new, params), new, reward, jnp.bool_(False), truncated, info

    def step(self, key: jax.Array, state: FootballState, action: jax.Array,
             params: FootballParams | None = None):
        """Auto-resetting step, as ``Environment.step``, minus its key split.

        ``reset_env`` ignores its key (every match starts from the same kick-off), so
        the split the base class makes for it would only cost a threefry call per step.
        """
        if params is None:
            params = self.default_params
        obs_st, state_st, reward, terminated, truncated, info = self.step_env(key, state, action, params)
        obs_re, state_re = self.reset_env(key, params)
        done = jnp.logical_or(terminated, truncated)
        state = select_tree(done, state_re, state_st)
        obs = jnp.where(done, obs_re, obs_st)
        info = dict(info)
        info["final_observation"] = obs_st
        return obs, state, reward, terminated, truncated, info

    def action_space(self, params: FootballParams | None = None) -> spaces.Discrete:
        return spaces.Discrete(C.BUILTIN_AI + 1, shape=(C.NUM_PLAYERS,))

    def observation_space(self, params: FootballParams | None = None) -> spaces.Box:
        return spaces.Box(-jnp.inf, jnp.inf, (OBSERVATION_SIZES[self.observation],), jnp.float32)

    @property
    def primitive_action_names(self) -> tuple[str, ...]:
        # Multi-discrete (11 players): hierarchies over football choose templates only.
        return ()

    def render(self, state: FootballState, params: FootballParams | None = None):
        from smjax.envs.football.render import render_frame
        return render_frame(state)

    def templates(self) -> dict:
        from smjax.envs.football.templates import make_templates
        return make_templates()

    def hierarchies(self) -> dict:
        from smjax.envs.football.templates import make_hierarchies
        return make_hierarchies(self)
