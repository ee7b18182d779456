"""``CraftEnv``: the Craft gridworld (Andreas et al. 2017, as used by Sticky Mittens) in JAX.

Actions: Discrete(5) = DOWN 0 (y-1), UP 1 (y+1), LEFT 2 (x-1), RIGHT 3 (x+1), USE 4.
``step_env`` also accepts NOOP = 5 (not in the action space) so that an impossible teleport
is a do-nothing step. Rules in ``dynamics``, world generation in ``worldgen``,
observations in ``observation``, templates and hierarchies in ``templates``.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.core import spaces
from smjax.core.env import Environment, select_tree
from smjax.core.overrides import INT32_MAX, parse_bool, parse_choice, parse_int
from smjax.core.registry import register
from smjax.envs.craft import constants as C
from smjax.envs.craft import dynamics, observation, templates, worldgen
from smjax.envs.craft.render import render_state
from smjax.envs.craft.structs import (
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

    def new_state(self, key: jax.Array) -> CraftState:
        """A freshly generated world (ignores any fixed map)."""
        grid, pos = worldgen.generate(key, self.config.world)
        return CraftState(
            grid=grid,
            pos=pos,
            direction=jnp.int32(C.DOWN),
            inventory=jnp.zeros(C.NUM_KINDS, jnp.int32),
            step=jnp.int32(0),
        )

    def initial_state(self, key: jax.Array, params: CraftParams) -> CraftState:
        """The state ``reset_env`` starts from (a fresh world, or the fixed map)."""
        fresh = self.new_state(key)
        fixed = CraftState(
            grid=params.fixed_grid,
            pos=params.fixed_pos,
            direction=params.fixed_direction,
            inventory=jnp.zeros(C.NUM_KINDS, jnp.int32),
            step=jnp.int32(0),
        )
        return select_tree(params.use_fixed_map, fixed, fresh)

    def reset_env(self, key: jax.Array, params: CraftParams) -> tuple[jax.Array, CraftState]:
        state = self.initial_state(key, params)
        return self.get_obs(state, params), state

    def step(self, key: jax.Array, state: CraftState, action: jax.Array,
             params: CraftParams | None = None):
        """Auto-resetting step, same contract as ``Environment.step``.

        Selects the next *state* first and observes it once; the pre-reset observation is
        computed separately for ``info["final_observation"]``, so a caller that ignores it
        lets XLA drop that second (expensive) observation.
        """
        if params is None:
            params = self.default_params
        key_step, key_reset = jax.random.split(key)
        _, state_st, reward, terminated, truncated, info = self.step_env(
            key_step, state, action, params
        )
        done = jnp.logical_or(terminated, truncated)
        next_state = select_tree(done, self.initial_state(key_reset, params), state_st)
        info = dict(info)
        info["final_observation"] = self.get_obs(state_st, params)
        return self.get_obs(next_state, params), next_state, reward, terminated, truncated, info

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

    @property
    def primitive_action_names(self) -> tuple[str, ...]:
        return C.ACTION_NAMES

    def render(self, state: CraftState, params: CraftParams | None = None):
        return render_state(state.grid, state.pos, state.direction, state.inventory)

    def templates(self) -> dict:
        if self._templates is None:
            self._templates = templates.make_templates()
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
    map_seed: int = 0,
) -> tuple[CraftEnv, CraftParams]:
    """Build ``(env, params)`` for a Craft task, validating every override value."""
    observation = parse_choice("observation", observation, OBSERVATIONS)
    fixed_map = parse_bool("fixed_map", fixed_map)
    if max_steps is not None:
        max_steps = parse_int("max_steps", max_steps, 1, INT32_MAX)
    map_seed = parse_int("map_seed", map_seed, 0, INT32_MAX)
    env = CraftEnv(CraftConfig(task=task, observation=observation))
    fixed_state = env.new_state(jax.random.key(map_seed)) if fixed_map else None
    return env, make_params(task, max_steps=max_steps, fixed_state=fixed_state)


def _factory(task: str):
    def factory(
        *,
        observation: str = "paper",
        fixed_map: bool = False,
        max_steps: int | None = None,
        map_seed: int = 0,
    ) -> tuple[CraftEnv, CraftParams]:
        return make_craft(task, observation=observation, fixed_map=fixed_map,
                          max_steps=max_steps, map_seed=map_seed)

    factory.__doc__ = f"craft/{task}: overrides observation, fixed_map, max_steps, map_seed."
    return factory


def register_all() -> None:
    for task, goal in C.TASKS.items():
        verb = "get" if goal in C.PRIMITIVES else "make"
        register(
            f"craft/{task}",
            _factory(task),
            f"Craft: {verb} {goal} ({C.world_kind(task)} world, cap {C.STEP_CAP[goal]} steps)",
        )
