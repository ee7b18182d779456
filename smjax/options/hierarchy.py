"""Hierarchies declared as data and validated on construction.

A hierarchy names a root option (the task: its reward is the environment's reward and
its episode the environment's episode) and, for every learnable option, the actions it
chooses among: template names, primitive action names, or ``"primitives"`` for all of
them. Templates without children are leaves: they are never learned and are always
realised by their teleport or controller.

Indices used by the compiled machinery:

* options: 0 is the root, ``1..T`` the templates in top-down (breadth-first) order;
* actions: ``0..P-1`` the primitive actions, ``P + j - 1`` a call of template ``j``.

An option with children may have a **scripted policy** (``policies``): a pure function
``policy(key, state, params, mask) -> int``, the index of the child it calls (into
``children[option]``), given the environment's state and ``mask``, bool [num_children]:
the children it may call now (initiation and realisability). It decides for that option
wherever nothing learned does: the option's own learner and its frozen policy (once
learned) come first. Like a controller, it gives way to the option's teleport where
teleports are on. A hierarchy whose every option with children has one is played
entirely by hand (evaluation needs no agent: ``HierarchyRunner(..., agent=None)``).

The root's success (what the trainer's threshold and ``final_success`` measure) is, in
this order: the hierarchy's declared ``success(state, params)`` evaluated on the state an
episode ends in, the environment's ``info["success"]`` where it reports one, else the
episode's return.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from smjax.options.hierarchy_checks import (
    ALL_PRIMITIVES as ALL_PRIMITIVES, HierarchyError, check_declaration,
    check_reachable_and_realisable, checked_policies, expand_children, option_order,
)
from smjax.options.template import OptionTemplate


@dataclass(frozen=True)
class Hierarchy:
    task: str
    children: Mapping[str, Sequence[str]]
    templates: Mapping[str, OptionTemplate]
    primitive_names: tuple[str, ...] = ()
    #: The task's success of an episode, from the state it ends in: pure and jittable,
    #: ``success(state, params)`` -> a scalar float in [0, 1] or a bool (None: the
    #: environment's ``info["success"]``, else the episode return).
    success: Callable[[Any, Any], Any] | None = None
    #: The best task success an episode can reach (1.0: no lower bound is known). Craft's
    #: success is its return, and a task whose recipe leaves items over can never reach 1
    #: (make_bench: 0.8); the trainer keeps a root threshold below it
    #: (TrainConfig.ceiling_fraction).
    success_ceiling: float = 1.0
    #: option name -> scripted policy ``policy(key, state, params, mask) -> int`` child
    #: index (pure and jittable; see the module docstring). None: no scripted policies.
    policies: Mapping[str, Callable[[Any, Any, Any, Any], Any]] | None = None
    # derived on construction
    option_names: tuple[str, ...] = field(init=False)
    depth_of: Mapping[str, int] = field(init=False)

    def __post_init__(self):
        check_declaration(self.task, self.children, self.templates, self.primitive_names,
                          self.success, self.success_ceiling)
        expanded = {p: tuple(expand_children(p, kids, self.task, self.templates,
                                             self.primitive_names))
                    for p, kids in self.children.items()}
        object.__setattr__(self, "children", expanded)
        object.__setattr__(self, "policies", checked_policies(self.policies, expanded))
        order, depth = option_order(self.task, expanded, self.templates)
        object.__setattr__(self, "option_names", tuple(order))
        object.__setattr__(self, "depth_of", depth)
        check_reachable_and_realisable(self.task, order, depth, expanded, self.templates,
                                       self.policies)

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
    def scripted(self) -> tuple[str, ...]:
        """Options with a scripted policy, in option order."""
        return tuple(n for n in self.option_names if n in self.policies)

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

    def flattened(self) -> "Hierarchy":
        """The flat baseline of this hierarchy: one level, the root choosing among every
        leaf (primitive actions and templates without children), the skills at the bottom
        of the hierarchy first (deepest first, then in option order), with the same task
        success. Scripted policies are dropped: the flat root learns. (For the built-in
        hierarchies this is exactly their catalogue's ``flat``.)"""
        leaves = [n for n in self.option_names[1:] if not self.children.get(n)]
        leaves.sort(key=lambda n: -self.depth_of[n])  # stable: option order within a depth
        primitives = [p for p in self.primitive_names if self.uses_primitives]
        return Hierarchy(task=self.task, children={self.task: primitives + leaves},
                         templates={n: self.templates[n] for n in leaves},
                         primitive_names=self.primitive_names, success=self.success,
                         success_ceiling=self.success_ceiling)

    def describe(self) -> str:
        lines = []
        for name in self.option_names:
            kids = self.children.get(name)
            what = ", ".join(kids) if kids else "(leaf: teleport/controller only)"
            if name in self.policies:
                what += " [scripted policy]"
            lines.append(f"level {self.level(name)}: {name} -> {what}")
        return "\n".join(lines)


def declare(env, task: str, children: Mapping[str, Sequence[str]], *,
            templates: Mapping[str, OptionTemplate] | Sequence[OptionTemplate] | None = None,
            success: Callable[[Any, Any], Any] | None = None,
            policies: Mapping[str, Callable[[Any, Any, Any, Any], Any]] | None = None,
            success_ceiling: float = 1.0) -> Hierarchy:
    """Build a validated hierarchy over an environment's templates and primitive actions.

    ``templates``: templates of your own (a name -> template mapping or a list), added to
    the environment's (one with the name of an environment template replaces it).
    ``success(state, params)``: the task's success of an episode ending in ``state`` (a
    float in [0, 1] or a bool), where it is not the environment's ``info["success"]`` or
    the episode return.
    ``policies``: option name -> scripted policy ``policy(key, state, params, mask)`` ->
    the index of the child to call (see the module docstring).
    ``success_ceiling``: the best task success an episode can reach, where it is below 1."""
    own = dict(env.templates())
    if templates is not None:
        items = templates.values() if isinstance(templates, Mapping) else templates
        for tpl in items:
            if not isinstance(tpl, OptionTemplate):
                raise HierarchyError(f"templates must be OptionTemplates, got {type(tpl).__name__}")
            own[tpl.name] = tpl
        if isinstance(templates, Mapping):
            bad = [k for k, t in templates.items() if k != t.name]
            if bad:
                raise HierarchyError(f"template registered as {bad[0]!r} is named "
                                     f"{templates[bad[0]].name!r}")
    hierarchy = Hierarchy(
        task=task,
        children=dict(children),
        templates=own,
        primitive_names=tuple(env.primitive_action_names),
        success=success,
        policies=policies,
        success_ceiling=success_ceiling,
    )
    _check_own_templates_used(hierarchy, templates)
    return hierarchy


def _check_own_templates_used(h: Hierarchy, templates) -> None:
    """Refuse a template the caller declared that the task never reaches (the environment's
    own templates may go unused: a hierarchy picks among them)."""
    if templates is None:
        return
    names = [t.name for t in (templates.values() if isinstance(templates, Mapping) else templates)]
    unused = [n for n in names if n not in h.depth_of]
    if unused:
        raise HierarchyError(f"template(s) {sorted(unused)} are declared but never reachable from "
                             f"the task {h.task!r}; list them as children or drop them")


def check_success(h: Hierarchy, env, env_params) -> None:
    """Raise ``HierarchyError`` unless ``h.success`` (if declared) maps one of ``env``'s
    states to a numeric or bool scalar (checked on shapes only: nothing runs)."""
    if h.success is None:
        return
    try:
        state = jax.eval_shape(lambda k: env.reset_env(k, env_params)[1], jax.random.PRNGKey(0))
        out = jax.eval_shape(lambda s: h.success(s, env_params), state)
    except Exception as err:  # the user's function, traced on the environment's state
        raise HierarchyError(f"success(state, params) of hierarchy {h.task!r} fails on the "
                             f"environment's state: {type(err).__name__}: {err}") from err
    leaves = jax.tree.leaves(out)
    ok = (len(leaves) == 1 and hasattr(leaves[0], "shape") and leaves[0].shape in ((), (1,))
          and (jnp.issubdtype(leaves[0].dtype, jnp.number) or leaves[0].dtype == jnp.bool_))
    if not ok:
        got = (f"shape {leaves[0].shape}, dtype {leaves[0].dtype}"
               if len(leaves) == 1 and hasattr(leaves[0], "shape") else repr(out))
        raise HierarchyError(f"success(state, params) of hierarchy {h.task!r} must return one "
                             f"scalar (a float in [0, 1] or a bool) per state, got {got}")
