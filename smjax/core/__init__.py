"""Environment protocol, spaces, registry and wrappers."""
from smjax.core import spaces
from smjax.core.env import Environment, select_tree
from smjax.core.registry import get_entry, make, register, registry
from smjax.core.version import warn_if_shadowed
from smjax.core.wrappers import EpisodeStatistics, LegacyGymnaxStep

__all__ = [
    "Environment", "select_tree", "spaces", "make", "register", "registry", "get_entry",
    "EpisodeStatistics", "LegacyGymnaxStep",
]

warn_if_shadowed()
