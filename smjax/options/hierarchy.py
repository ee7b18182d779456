"""Hierarchies declared as data and validated on construction.

A hierarchy names a root option (the task: its reward is the environment's reward and
its episode the environment's episode) and, for every learnable option, the actions it
chooses among: template names, primitive action names, or ``"primitives"`` for all of
them. Templates without children are leaves: they are never learned and are always
realised by their teleport or controller.

Indices used by the compiled machinery:

* options: 0 is the root, ``1..T`` the templates in top-down (breadth-first) order;
* actions: ``0..P-1`` the primitive actions, ``P + j - 1`` a call of template ``j``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from smjax.options.template import OptionTemplate

ALL_PRIMITIVES = "primitives"


class HierarchyError(ValueError):
    """A hierarchy declaration is malformed; the message names the culprit."""


@dataclass(frozen=True)
class Hierarchy:
    task: str
    children: Mapping[str, Sequence[str]]
    templates: Mapping[str, OptionTemplate]
    primitive_names: tuple[str, ...] = ()
    # derived on construction
    option_names: tuple[str, ...] = field(init=False)
    depth_of: Mapping[str, int] = field(init=False)

    def __post_init__(self):
        if not isinstance(self.task, str) or not self.task:
            raise HierarchyError(f"hierarchy task must be a non-empty name, got {self.task!r}")
        non_names = [k for k in self.children if not isinstance(k, str)]
        if non_names:  # checked first: later messages sort and compare names
            raise HierarchyError(f"option names must be strings, got {non_names!r}")
        if self.task in self.templates:
            raise HierarchyError(
                f"task {self.task!r} is also a template name; the root option needs its own name"
            )
        if self.task not in self.children:
            raise HierarchyError(
                f"hierarchy for task {self.task!r} declares no children for the task itself; "
                f"declared: {sorted(self.children)}"
            )
        for name, tpl in self.templates.items():
            if tpl.name != name:
                raise HierarchyError(f"template registered as {name!r} is named {tpl.name!r}")
        expanded = {p: tuple(self._expand(p, kids)) for p, kids in self.children.items()}
        object.__setattr__(self, "children", expanded)
        order, depth = self._walk()
        object.__setattr__(self, "option_names", tuple(order))
        object.__setattr__(self, "depth_of", depth)
        for name in order[1:]:
            tpl = self.templates[name]
            if not tpl.realisable and not self.children.get(name):
                raise HierarchyError(
                    f"template {name!r} has no way to be realised: no teleport, no controller "
                    f"and no children to learn a policy over"
                )
            if not tpl.realisable:
                raise HierarchyError(
                    f"template {name!r} has neither a teleport nor a controller, so its callers "
                    f"cannot run it before it is learned"
                )

    # ---- construction helpers ------------------------------------------
    def _expand(self, parent: str, kids: Sequence[str]) -> list[str]:
        if isinstance(kids, str) or not isinstance(kids, Sequence):
            raise HierarchyError(
                f"children of {parent!r} must be a list of names, got {type(kids).__name__}"
            )
        if parent != self.task and parent not in self.templates:
            raise HierarchyError(
                f"children declared for unknown option {parent!r}; known templates: "
                f"{sorted(self.templates)}"
            )
        out: list[str] = []
        for kid in kids:
            if not isinstance(kid, str):
                raise HierarchyError(f"{parent!r} lists a child that is not a name: {kid!r}")
            if kid == ALL_PRIMITIVES:
                if not self.primitive_names:
                    raise HierarchyError(
                        f"{parent!r} asks for primitive actions, but this environment has no "
                        f"discrete primitive actions"
                    )
                out.extend(p for p in self.primitive_names if p not in out)
            elif kid in self.primitive_names or kid in self.templates:
                if kid not in out:
                    out.append(kid)
            else:
                raise HierarchyError(
                    f"{parent!r} lists unknown child {kid!r}; valid: templates "
                    f"{sorted(self.templates)}, primitives {list(self.primitive_names)} "
                    f"or {ALL_PRIMITIVES!r}"
                )
        if not out:
            raise HierarchyError(f"option {parent!r} has an empty list of children")
        return out

    def _walk(self) -> tuple[list[str], dict[str, int]]:
        # Cycle check by depth-first search, then breadth-first order for levels.
        state: dict[str, int] = {}

        def visit(name: str, path: list[str]) -> None:
            state[name] = 1
            for kid in self.children.get(name, ()):
                if kid not in self.templates:
                    continue
                if state.get(kid) == 1:
                    cycle = path[path.index(kid):] + [kid] if kid in path else [name, kid]
                    raise HierarchyError(f"hierarchy has a cycle: {' -> '.join(cycle)}")
                if state.get(kid) is None:
                    visit(kid, path + [kid])
            state[name] = 2

        visit(self.task, [self.task])
        order, depth = [self.task], {self.task: 0}
        frontier = [self.task]
        while frontier:
            nxt = []
            for name in frontier:
                for kid in self.children.get(name, ()):
                    if kid in self.templates and kid not in depth:
                        depth[kid] = depth[name] + 1
                        order.append(kid)
                        nxt.append(kid)
            frontier = nxt
        return order, depth

    # ---- views used by trainers -----------------------------------------
    @property
    def num_options(self) -> int:
        return len(self.option_names)

    @property
    def uses_primitives(self) -> bool:
        return any(k in self.primitive_names for kids in self.children.values() for k in kids)

    @property
    def num_primitives(self) -> int:
        return len(self.primitive_names) if self.uses_primitives else 0

    @property
    def num_actions(self) -> int:
        return self.num_primitives + self.num_options - 1

    @property
    def stack_depth(self) -> int:
        """D: the most options that can be on the execution stack at once."""
        return max(self.depth_of.values()) + 1

    def level(self, name: str) -> int:
        """The paper's level of an option's learner (the root's policy is level 1)."""
        return self.depth_of[name] + 1

    def option_index(self, name: str) -> int:
        return self.option_names.index(name)

    def action_index(self, name: str) -> int:
        if name in self.primitive_names:
            return self.primitive_names.index(name)
        return self.num_primitives + self.option_index(name) - 1

    @property
    def learnable(self) -> tuple[str, ...]:
        """Options with children, top-down (level) order; the root first."""
        return tuple(n for n in self.option_names if self.children.get(n))

    @property
    def template_list(self) -> tuple[OptionTemplate, ...]:
        return tuple(self.templates[n] for n in self.option_names[1:])

    def child_mask(self) -> np.ndarray:
        """bool [num_options, num_actions]: which actions each option may choose."""
        mask = np.zeros((self.num_options, self.num_actions), bool)
        for i, name in enumerate(self.option_names):
            for kid in self.children.get(name, ()):
                mask[i, self.action_index(kid)] = True
        return mask

    def describe(self) -> str:
        lines = []
        for name in self.option_names:
            kids = self.children.get(name)
            what = ", ".join(kids) if kids else "(leaf: teleport/controller only)"
            lines.append(f"level {self.level(name)}: {name} -> {what}")
        return "\n".join(lines)


def declare(env, task: str, children: Mapping[str, Sequence[str]]) -> Hierarchy:
    """Build a validated hierarchy over an environment's templates and primitive actions."""
    return Hierarchy(
        task=task,
        children=dict(children),
        templates=dict(env.templates()),
        primitive_names=tuple(env.primitive_action_names),
    )
