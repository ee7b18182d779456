"""Craft: the gridworld of the Sticky Mittens paper, in pure JAX.

Importing this package registers all 24 tasks (``craft/get_<primitive>``,
``craft/make_<crafted>``) with ``smjax.make``.

    env, params = smjax.make("craft/get_gem", observation="paper")
    obs, state = env.reset(key, params)
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)
"""
from smjax.envs.craft import constants
from smjax.envs.craft.ascii import (
    REFERENCE_GEM_MAP, REFERENCE_GOLD_MAP, from_ascii, inventory_dict, parse_ascii, to_ascii,
)
from smjax.envs.craft.env import CraftEnv, make_craft, register_all
from smjax.envs.craft.types import CraftConfig, CraftParams, CraftState, make_params
from smjax.envs.craft.templates import default_hierarchy_name, hierarchy_names

TASKS = tuple(constants.TASKS)

register_all()

__all__ = [
    "CraftEnv", "CraftConfig", "CraftParams", "CraftState", "make_craft", "make_params",
    "from_ascii", "to_ascii", "parse_ascii", "inventory_dict", "REFERENCE_GOLD_MAP",
    "REFERENCE_GEM_MAP", "default_hierarchy_name", "hierarchy_names", "TASKS", "constants",
]
