"""11 vs 11 football in pure JAX (Google Research Football's rules and coordinates).

Registers ``football/11v11_easy``, ``football/11v11_medium`` and ``football/11v11_hard``
(opponent difficulty 0.05 / 0.6 / 0.95). Overrides: ``observation`` ("simple115" or
"paper"), ``game_length`` (3000; ``params.max_steps``, the traced episode cap, starts at
it), ``checkpoint_reward`` (False) and ``difficulty`` (None = the task's level).

Where things are (each module's docstring documents the rules it implements). The
modules every environment package has: types (state, params, the per-tick random draws'
struct), reset (kick-off setup: every episode starts from the same state), dynamics (one
environment step: the agent's and the AI's actions, a game tick, reward, truncation),
observation (both layouts, every index), templates (option templates and hierarchies),
render, env (``FootballEnv``, its task factories and their registration). Football's own:
constants (pitch, formation, action ids, physics constants), noise (a tick's random
draws from one key), physics (sticky controls, movement, passes, shots, ball flight),
rules (possession, tackles, fouls, goals, out of play, restarts, ``step_game``),
builtin_ai (the one AI both teams use and how difficulty acts), mirror (the pitch turned
180 degrees with the teams swapped), match (AI-vs-AI ``play_match``).
"""
from __future__ import annotations

from smjax.envs.football.env import DIFFICULTIES, FootballEnv, register_all
from smjax.envs.football.match import play_match
from smjax.envs.football.mirror import mirror_state
from smjax.envs.football.reset import initial_state
from smjax.envs.football.types import FootballParams, FootballState

register_all()

__all__ = ["FootballEnv", "FootballParams", "FootballState", "DIFFICULTIES",
           "play_match", "initial_state", "mirror_state"]
