"""Which hierarchy a run used, as a name results.json and a saved policy record, and back.

Names: a catalogue entry of the environment (``env.hierarchies()``, e.g. "paper"), one
declared by the caller (``declared:<task>``: its functions live in the caller's code, so
loading needs the same ``Hierarchy`` passed again), either with ``:flattened`` for the
flat method, or ``primitives:flattened`` (flat over the primitive actions alone, for an
environment that declares no hierarchy).
"""
from __future__ import annotations

from smjax.options.hierarchy import Hierarchy, declare

FLAT_SUFFIX = ":flattened"
PRIMITIVES_ONLY = "primitives" + FLAT_SUFFIX
DECLARED_PREFIX = "declared:"


def declared_identity(h: Hierarchy) -> dict:
    """What a resume or a saved policy must find again of a declared hierarchy (its shape
    and template names; the templates' functions cannot be compared)."""
    identity = {"task": h.task, "children": {k: list(v) for k, v in h.children.items()},
                "templates": sorted(h.templates)}
    if h.success is not None:  # only where declared, so checkpoints without it still resume
        identity["success"] = getattr(h.success, "__qualname__", type(h.success).__name__)
    if h.policies:  # scripted options (only where declared, as above)
        identity["policies"] = sorted(h.policies)
    return identity


def hierarchy_named(env, name: str, declared: Hierarchy | None = None) -> Hierarchy:
    """The hierarchy ``name`` stands for over ``env``; a ``declared:`` name is ``declared``
    (the caller's own), flattened where the name says so. ValueError for a name the
    environment's catalogue does not hold."""
    if name == PRIMITIVES_ONLY:
        return declare(env, "task", {"task": ["primitives"]})
    base = name.removesuffix(FLAT_SUFFIX)
    if base.startswith(DECLARED_PREFIX):
        if declared is None:
            raise ValueError(f"{name!r} is a hierarchy declared in code; pass the same "
                             f"Hierarchy (hierarchy=...)")
        chosen = declared
    else:
        options = env.hierarchies()
        if not options:
            raise ValueError(f"environment {env.name!r} declares no hierarchies")
        if base not in options:
            shown = base if len(base) <= 80 else base[:77] + "..."  # a name may be a whole file
            raise ValueError(
                f"unknown hierarchy {shown!r} for {env.name!r}; valid: {', '.join(options)}")
        chosen = options[base]
    return chosen.flattened() if name.endswith(FLAT_SUFFIX) else chosen
