"""The rules a hierarchy declaration must meet, checked as ``Hierarchy`` is built.

Each check raises ``HierarchyError`` with a message that names the culprit.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from smjax.options.template import OptionTemplate

ALL_PRIMITIVES = "primitives"


class HierarchyError(ValueError):
    """A hierarchy declaration is malformed; the message names the culprit."""


def check_declaration(task: Any, children: Mapping, templates: Mapping[str, OptionTemplate],
                      primitive_names: tuple[str, ...], success: Any, success_ceiling: Any) -> None:
    """The task's name, the option names, ``success`` and ``success_ceiling``, and that every
    template is registered under its own name."""
    if not isinstance(task, str) or not task:
        raise HierarchyError(f"hierarchy task must be a non-empty name, got {task!r}")
    non_names = [k for k in children if not isinstance(k, str)]
    if non_names:  # checked first: later messages sort and compare names
        raise HierarchyError(f"option names must be strings, got {non_names!r}")
    if task in templates:
        raise HierarchyError(
            f"task {task!r} is also a template name; the root option needs its own name"
        )
    if task in primitive_names or task == ALL_PRIMITIVES:
        raise HierarchyError(f"task {task!r} is also a primitive action's name; the root "
                             f"option needs its own name")
    if success is not None and not callable(success):
        raise HierarchyError(
            f"success must be a function success(state, params) -> float in [0, 1] or "
            f"bool, got {type(success).__name__}"
        )
    if isinstance(success_ceiling, bool) or not isinstance(success_ceiling, (int, float)) \
            or not 0 < success_ceiling <= 1:
        raise HierarchyError(
            f"success_ceiling must be a number in (0, 1], got {success_ceiling!r}")
    if task not in children:
        raise HierarchyError(
            f"hierarchy for task {task!r} declares no children for the task itself; "
            f"declared: {sorted(children)}"
        )
    for name, tpl in templates.items():
        if tpl.name != name:
            raise HierarchyError(f"template registered as {name!r} is named {tpl.name!r}")


def expand_children(parent: str, kids: Sequence[str], task: str,
                    templates: Mapping[str, OptionTemplate],
                    primitive_names: tuple[str, ...]) -> list[str]:
    """``parent``'s children as a list of names without repeats, ``ALL_PRIMITIVES`` spelt
    out as every primitive action."""
    if isinstance(kids, str) or not isinstance(kids, Sequence):
        raise HierarchyError(
            f"children of {parent!r} must be a list of names, got {type(kids).__name__}"
        )
    if parent != task and parent not in templates:
        raise HierarchyError(
            f"children declared for unknown option {parent!r}; known templates: "
            f"{sorted(templates)}"
        )
    out: list[str] = []
    for kid in kids:
        if not isinstance(kid, str):
            raise HierarchyError(f"{parent!r} lists a child that is not a name: {kid!r}")
        if kid == ALL_PRIMITIVES:
            if not primitive_names:
                raise HierarchyError(
                    f"{parent!r} asks for primitive actions, but this environment has no "
                    f"discrete primitive actions"
                )
            out.extend(p for p in primitive_names if p not in out)
        elif kid in primitive_names or kid in templates:
            if kid not in out:
                out.append(kid)
        else:
            raise HierarchyError(
                f"{parent!r} lists unknown child {kid!r}; valid: templates "
                f"{sorted(templates)}, primitives {list(primitive_names)} "
                f"or {ALL_PRIMITIVES!r}"
            )
    if not out:
        raise HierarchyError(f"option {parent!r} has an empty list of children")
    return out


def checked_policies(policies: Any, children: Mapping[str, Sequence[str]]) -> dict:
    """The scripted policies as a dict (None: none), each keyed by an option with children."""
    if policies is None:
        return {}
    if not isinstance(policies, Mapping):
        raise HierarchyError(f"policies must map option names to scripted policies, got "
                             f"{type(policies).__name__}")
    for name, fn in policies.items():
        if not isinstance(name, str) or name not in children:
            raise HierarchyError(
                f"scripted policy for {name!r}, which is not an option with children; "
                f"options with children: {sorted(children)}")
        if not callable(fn):
            raise HierarchyError(
                f"scripted policy of {name!r} must be a function policy(key, state, "
                f"params, mask) -> child index, got {type(fn).__name__}")
    return dict(policies)


def option_order(task: str, children: Mapping[str, Sequence[str]],
                 templates: Mapping[str, OptionTemplate]) -> tuple[list[str], dict[str, int]]:
    """(options in breadth-first order from the task, option -> depth), refusing a cycle."""
    _refuse_cycles(task, children, templates)
    order, depth = [task], {task: 0}
    frontier = [task]
    while frontier:
        nxt = []
        for name in frontier:
            for kid in children.get(name, ()):
                if kid in templates and kid not in depth:
                    depth[kid] = depth[name] + 1
                    order.append(kid)
                    nxt.append(kid)
        frontier = nxt
    return order, depth


def _refuse_cycles(task: str, children: Mapping[str, Sequence[str]],
                   templates: Mapping[str, OptionTemplate]) -> None:
    """Depth-first search from the task; a template met again on its own path is a cycle."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(name: str, path: list[str]) -> None:
        state[name] = 1
        for kid in children.get(name, ()):
            if kid not in templates:
                continue
            if state.get(kid) == 1:
                cycle = path[path.index(kid):] + [kid] if kid in path else [name, kid]
                raise HierarchyError(f"hierarchy has a cycle: {' -> '.join(cycle)}")
            if state.get(kid) is None:
                visit(kid, path + [kid])
        state[name] = 2

    visit(task, [task])


def check_reachable_and_realisable(task: str, order: Sequence[str], depth: Mapping[str, int],
                                   children: Mapping[str, Sequence[str]],
                                   templates: Mapping[str, OptionTemplate],
                                   policies: Mapping) -> None:
    """Every option with children is reachable from the task, and every template below the
    root can run before it is learned (teleport or controller) unless a script plays it."""
    orphans = [name for name in children if name not in depth]
    if orphans:  # its children would never be chosen: a mistake in the declaration
        raise HierarchyError(f"option(s) {sorted(orphans)} have children declared but are "
                             f"never reachable from the task {task!r}; list them as a "
                             f"child of an option that is, or drop them")
    for name in order[1:]:
        tpl = templates[name]
        if name in policies:  # it decides by its script: nothing else is needed
            continue
        if not tpl.realisable and not children.get(name):
            raise HierarchyError(
                f"template {name!r} has no way to be realised: no teleport, no controller "
                f"and no children to learn a policy over"
            )
        if not tpl.realisable:
            raise HierarchyError(
                f"template {name!r} has neither a teleport nor a controller, so its callers "
                f"cannot run it before it is learned"
            )
