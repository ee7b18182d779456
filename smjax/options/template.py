"""Option templates: an initiation set, a termination condition and a way to be realised.

A template is data plus pure functions of (state, params); it knows nothing about any
environment. Before its policy is learned it is realised either by a **teleport** (the
environment jumps to an outcome of the skill in one step) or by a scripted
**controller** (played tick by tick until ``satisfied`` or ``k_max``).

Signatures (all jittable, unbatched; vmap them for batches):

* ``initiation(state, params) -> bool``: may the template be called here?
* ``satisfied(state, params) -> bool``: F_o, the outcome the template promises.
* ``teleport(key, state, params) -> (state, action)``: jump to an outcome and name the
  primitive action to execute in that same tick, so a teleport is exactly one
  environment step (Craft: stand next to X facing it, then USE).
* ``controller(key, state, params) -> action``: the scripted primitive action.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Optional

import jax
import jax.numpy as jnp

StateFn = Callable[[Any, Any], jax.Array]
TeleportFn = Callable[[jax.Array, Any, Any], tuple[Any, jax.Array]]
ControllerFn = Callable[[jax.Array, Any, Any], jax.Array]


@dataclass(frozen=True, eq=False)
class Parametric:
    """A realisation shared by a family of templates, each with its own data.

    ``Parametric(fn, data)(key, state, params) == fn(key, state, params, data)``. Use it
    for a teleport or controller that differs between templates only by data (Craft's
    "give X" for each X, Fetch's "reach block i" for each i): the runner then evaluates
    one call per family per tick, with each environment's data gathered for the
    template it runs, instead of one call per template (under ``vmap`` every call runs
    for every environment). ``data`` is a pytree of arrays with the same structure for
    every member of a family.
    """

    fn: Callable[..., Any]
    data: Any

    def __call__(self, key: jax.Array, state: Any, params: Any):
        return self.fn(key, state, params, self.data)


def always(state: Any, params: Any) -> jax.Array:
    """Initiation set that holds everywhere."""
    return jnp.asarray(True)


@dataclass(frozen=True)
class OptionTemplate:
    """An option template a_o = (I, T, P) plus how to realise it before it is learned.

    Attributes:
      name: unique name used in hierarchies.
      satisfied: F_o, True when the template's outcome holds.
      k_max: tick budget; an option running this long is popped (T = F_o or k > k_max).
      initiation: I; calls outside it are masked out of the caller's choices.
      failed: optional condition that ends the option *without* its outcome (e.g. "the
        ball was lost" for an attack): the option pops, but a learner of this template
        earns nothing for it. Termination is satisfied or failed or k_max.
      teleport: realisation by jumping to an outcome (one tick), or None.
      controller: scripted realisation (runs until satisfied or k_max), or None.
      nominal_steps: d, the duration a teleported call stands for; the caller's SMDP
        discount for a teleport is gamma**d (the reference's gamma^d per template).
      description: one line for docs and ``--help``.
      side_cost: optional cost of what a state holds beyond the template's promise (a
        teleport lands with none of it; Craft: 0.1 per unit of items other than the one
        promised). Where the trainer asks (fine-tuning, ``TrainConfig.finetune_side_cost``)
        a learner of this template is also rewarded by its decrease ``c(s) - c(s')``, so
        what its run picks up and leaves behind costs it as the task's reward would; its
        F_o success is unchanged.
    """

    name: str
    satisfied: StateFn
    k_max: int
    initiation: StateFn = always
    failed: Optional[StateFn] = None
    teleport: Optional[TeleportFn] = None
    controller: Optional[ControllerFn] = None
    nominal_steps: int = 1
    description: str = ""
    side_cost: Optional[StateFn] = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"template name must be a non-empty string, got {self.name!r}")
        if int(self.k_max) < 1:
            raise ValueError(f"template {self.name!r}: k_max must be >= 1, got {self.k_max}")
        if int(self.nominal_steps) < 1:
            raise ValueError(
                f"template {self.name!r}: nominal_steps must be >= 1, got {self.nominal_steps}"
            )

    @property
    def realisable(self) -> bool:
        """True if the template can run before it is learned (teleport or controller)."""
        return self.teleport is not None or self.controller is not None


def teleport_step(env: Any, template: OptionTemplate, key: jax.Array, state: Any, params: Any):
    """Realise ``template`` by teleport as one environment step (no auto-reset).

    Returns ``env.step_env``'s six values after the jump.
    """
    if template.teleport is None:
        raise ValueError(f"template {template.name!r} has no teleport")
    key_tp, key_step = jax.random.split(key)
    jumped, action = template.teleport(key_tp, state, params)
    return env.step_env(key_step, jumped, action, params)
