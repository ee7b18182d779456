"""``FootballEnv``: 11 vs 11 football, the agent commands the whole left team.

Action: i32[11], one per left player: 0..18 the GRF actions (constants.ACTION_NAMES),
19 = let the built-in AI (at ``params.teammate_difficulty``) move that player. The
right team is always the built-in AI at ``params.difficulty``.

Reward (``dynamics``): +1 when the left team scores, -1 when it concedes; with
``params.checkpoint_reward`` also GRF's checkpoint shaping. Episodes never terminate;
they are truncated after ``params.max_steps`` ticks (``game_length`` sets its default).
Every episode starts from the same kick-off (``reset``), so the reset ignores its key.
info: ``score`` i32[2] (left, right), ``goal_difference`` (left - right), ``goals``
scored this tick i32[2].
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core import spaces
from smjax.core.overrides import INT32_MAX, parse_bool, parse_choice, parse_float, parse_int
from smjax.core.env import Environment
from smjax.core.registry import register
from smjax.envs.football import constants as C
from smjax.envs.football import dynamics, reset
from smjax.envs.football.observation import OBSERVATION_SIZES, observe
from smjax.envs.football.types import FootballParams, FootballState

DIFFICULTIES = {"easy": 0.05, "medium": 0.6, "hard": 0.95}


class FootballEnv(Environment[FootballState, FootballParams]):
    """11 vs 11 football in jax.numpy (static: the observation kind)."""

    # Every match starts from the same kick-off: the auto-reset needs no key of its own.
    reset_ignores_key = True

    def __init__(self, observation: str = "simple115", game_length: int = 3000,
                 difficulty: float = 0.6, checkpoint_reward: bool = False):
        self.observation = parse_choice("football observation", observation,
                                        sorted(OBSERVATION_SIZES))
        # strict: bool("False") is True and int(2.9) is 2; both would pass silently.
        # game_length is the default of params.max_steps (GRF's name for it)
        self.game_length = parse_int("game_length", game_length, 1, INT32_MAX)
        self._difficulty = parse_float("difficulty (easy 0.05, medium 0.6, hard 0.95)",
                                       difficulty, 0.0, 1.0)
        self._checkpoint_reward = parse_bool("checkpoint_reward", checkpoint_reward)

    @property
    def default_params(self) -> FootballParams:
        # numpy: making the task runs no XLA program (see craft's make_params)
        return FootballParams(difficulty=np.asarray(self._difficulty, np.float32),
                              teammate_difficulty=np.asarray(0.95, np.float32),
                              checkpoint_reward=np.asarray(self._checkpoint_reward),
                              max_steps=np.asarray(self.game_length, np.int32))

    def get_obs(self, state: FootballState, params: FootballParams | None = None) -> jax.Array:
        return observe(state, self.observation)

    def initial_state(self, key: jax.Array, params: FootballParams) -> FootballState:
        return reset.initial_state(0)   # the left team kicks off; the start is deterministic

    def step_env(self, key: jax.Array, state: FootballState, action: jax.Array, params: FootballParams):
        new, reward, terminated, truncated, info = dynamics.step(
            key, state, action, params)
        return self.get_obs(new, params), new, reward, terminated, truncated, info

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


def _factory(level: str):
    def make(*, observation: str = "simple115", game_length: int = 3000,
             checkpoint_reward: bool = False, difficulty: float | None = None):
        env = FootballEnv(observation=observation, game_length=game_length,
                          difficulty=DIFFICULTIES[level] if difficulty is None else difficulty,
                          checkpoint_reward=checkpoint_reward)
        return env, env.default_params
    return make


def register_all() -> None:
    """Register ``football/11v11_easy``, ``_medium`` and ``_hard``."""
    for level, value in DIFFICULTIES.items():
        register(f"football/11v11_{level}", _factory(level),
                 f"11 vs 11 football against the built-in AI at difficulty {value} ({level})")
