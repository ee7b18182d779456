"""``CraftEnv``: the Craft gridworld (Andreas et al. 2017, as used by Sticky Mittens) in JAX.

Actions: Discrete(5) = DOWN 0 (y-1), UP 1 (y+1), LEFT 2 (x-1), RIGHT 3 (x+1), USE 4.
``step_env`` also accepts NOOP = 5 (not in the action space) so that an impossible teleport
is a do-nothing step. The package's modules, one job each (the same names in every
environment package): ``types`` (state, params, static config), ``reset`` (world generation
and the initial state), ``dynamics`` (transition and reward), ``observation``, ``templates``
(option templates and hierarchies), ``render``, ``env`` (this class and its factory); and
Craft's own ``constants`` (kinds, recipes, tasks, step caps), ``ascii`` (maps as text) and
``bench`` (throughput).
"""
from __future__ import annotations

import jax

from smjax.core import spaces
from smjax.core.env import Environment
from smjax.core.overrides import INT32_MAX, parse_bool, parse_choice, parse_int
from smjax.core.registry import register
from smjax.envs.craft import constants as C
from smjax.envs.craft import dynamics, observation, reset, templates
from smjax.envs.craft.ascii import to_ascii
from smjax.envs.craft.render import render_state
from smjax.envs.craft.types import (
    OBSERVATIONS, CraftConfig, CraftParams, CraftState, make_params,
)


class CraftEnv(Environment[CraftState, CraftParams]):
    """One Craft task; ``config`` is static (task, observation kind)."""

    # reward: 1 for the goal item, less 0.1 per other item made, floored at 0, and the
    # episode ends with it, so an episode's return lies in [0, 1]
    success_in_unit_interval = True

    def __init__(self, config: CraftConfig | None = None):
        self.config = config if config is not None else CraftConfig()
        self.name = f"craft/{self.config.task}"
        self._obs_fn = observation.OBSERVATION_FNS[self.config.observation]
        self._templates = None
        self._hierarchies = None

    @property
    def default_params(self) -> CraftParams:
        return make_params(self.config.task)

    def initial_state(self, key: jax.Array, params: CraftParams) -> CraftState:
        """The state an episode starts from (a fresh world, or the fixed map).

        This hook is what makes ``Environment.step``'s auto-reset observe only the state
        it keeps (the paper observation is the expensive part of a step).
        """
        return reset.initial_state(key, params, self.config.world)

    def step_env(self, key: jax.Array, state: CraftState, action: jax.Array, params: CraftParams):
        next_state = dynamics.transition(state, action)
        reward, terminated, truncated = dynamics.reward_and_done(next_state, params)
        return self.get_obs(next_state, params), next_state, reward, terminated, truncated, {}

    def get_obs(self, state: CraftState, params: CraftParams | None = None) -> jax.Array:
        return self._obs_fn(state)

    def action_space(self, params: CraftParams | None = None) -> spaces.Discrete:
        return spaces.Discrete(C.NUM_ACTIONS)

    def observation_space(self, params: CraftParams | None = None) -> spaces.Box:
        return observation.observation_space(self.config.observation)

    def observation_layout(self, params: CraftParams | None = None) -> tuple:
        return observation.observation_layout(self.config.observation)

    @property
    def primitive_action_names(self) -> tuple[str, ...]:
        return C.ACTION_NAMES

    def render(self, state: CraftState, params: CraftParams | None = None):
        return render_state(state.grid, state.pos, state.direction, state.inventory)

    def describe(self, state: CraftState, params: CraftParams | None = None) -> str:
        """The map as ASCII (``ascii.to_ascii``: ``@`` the agent, the top row y = 11)."""
        return to_ascii(state)

    def templates(self) -> dict:
        if self._templates is None:
            self._templates = templates.make_templates(self.config.side_cost)
        return dict(self._templates)

    def hierarchies(self) -> dict:
        """name -> Hierarchy; the default ("paper" where defined, else "recipe") first."""
        if self._hierarchies is None:
            self._hierarchies = templates.make_hierarchies(self, self.config.task)
        return dict(self._hierarchies)


def make_craft(
    task: str,
    *,
    observation: str = "paper",
    fixed_map: bool = False,
    max_steps: int | None = None,
    map_seed: int | None = None,
    side_cost: str = "held",
) -> tuple[CraftEnv, CraftParams]:
    """Build ``(env, params)`` for a Craft task, validating every override value.
    ``side_cost``: what the ``give_X`` templates' side cost charges (fine-tuning's shaping):
    "held", every unit held but X; "surplus", only units beyond what X's recipe consumes;
    "leftover", as "surplus" until X is held, then as "held"."""
    observation = parse_choice("observation", observation, OBSERVATIONS)
    side_cost = parse_choice("side_cost", side_cost, templates.SIDE_COSTS)
    fixed_map = parse_bool("fixed_map", fixed_map)
    if max_steps is not None:
        max_steps = parse_int("max_steps", max_steps, 1, INT32_MAX)
    if map_seed is not None:
        map_seed = parse_int("map_seed", map_seed, 0, INT32_MAX)
        if not fixed_map:  # it would be ignored: every episode draws its own map
            raise ValueError(f"map_seed={map_seed} chooses the one fixed map, but the map is not "
                             f"fixed: add --fixed-map (fixed_map=true) or drop map_seed")
    env = CraftEnv(CraftConfig(task=task, observation=observation, side_cost=side_cost))
    fixed_state = (reset.new_state(jax.random.key(map_seed or 0), env.config.world)
                   if fixed_map else None)
    return env, make_params(task, max_steps=max_steps, fixed_state=fixed_state)


def _factory(task: str):
    def factory(
        *,
        observation: str = "paper",
        fixed_map: bool = False,
        max_steps: int | None = None,
        map_seed: int | None = None,
        side_cost: str = "held",
    ) -> tuple[CraftEnv, CraftParams]:
        return make_craft(task, observation=observation, fixed_map=fixed_map,
                          max_steps=max_steps, map_seed=map_seed, side_cost=side_cost)

    factory.__doc__ = (f"craft/{task}: overrides observation, fixed_map, max_steps, map_seed, "
                       "side_cost.")
    return factory


def register_all() -> None:
    for task, goal in C.TASKS.items():
        verb = "get" if goal in C.PRIMITIVES else "make"
        register(
            f"craft/{task}",
            _factory(task),
            f"Craft: {verb} {goal} ({C.world_kind(task)} world, cap {C.STEP_CAP[goal]} steps)",
        )
