"""11 vs 11 football in pure JAX (Google Research Football's rules and coordinates).

Registers ``football/11v11_easy``, ``football/11v11_medium`` and ``football/11v11_hard``
(opponent difficulty 0.05 / 0.6 / 0.95). Overrides: ``observation`` ("simple115" or
"paper"), ``game_length`` (3000), ``checkpoint_reward`` (False) and ``difficulty``
(None = the task's level).

Where things are (each module's docstring documents the rules it implements):
constants (pitch, formation, action ids, physics constants), state (state, params,
per-tick random draws, kick-off, the mirror map), physics (sticky controls, movement,
passes, shots, ball flight), rules (possession, tackles, fouls, goals, out of play,
restarts, ``step_game``), builtin_ai (the one AI both teams use and how difficulty acts),
match (AI-vs-AI ``play_match``), observation (both layouts, every index), templates
(option templates and hierarchies), render, env (``FootballEnv``: reward, info,
truncation).
"""
from __future__ import annotations

from smjax.core.registry import register
from smjax.envs.football.env import DIFFICULTIES, FootballEnv
from smjax.envs.football.match import play_match
from smjax.envs.football.state import FootballParams, FootballState, initial_state, mirror_state


def _factory(level: str):
    def make(*, observation: str = "simple115", game_length: int = 3000,
             checkpoint_reward: bool = False, difficulty: float | None = None):
        env = FootballEnv(observation=observation, game_length=game_length,
                          difficulty=DIFFICULTIES[level] if difficulty is None else difficulty,
                          checkpoint_reward=checkpoint_reward)
        return env, env.default_params
    return make


for _level, _value in DIFFICULTIES.items():
    register(f"football/11v11_{_level}", _factory(_level),
             f"11 vs 11 football against the built-in AI at difficulty {_value} ({_level})")

__all__ = ["FootballEnv", "FootballParams", "FootballState", "DIFFICULTIES",
           "play_match", "initial_state", "mirror_state"]
