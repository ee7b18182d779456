"""Option templates, hierarchies, the fixed-depth execution stack and the hierarchical tick.

Nothing in this package imports an environment module.
"""
from smjax.options.hierarchy import ALL_PRIMITIVES, Hierarchy, HierarchyError, declare
from smjax.options.template import OptionTemplate, Parametric, always, teleport_step

__all__ = [
    "OptionTemplate", "Parametric", "always", "teleport_step", "Hierarchy", "HierarchyError", "declare",
    "ALL_PRIMITIVES",
]
