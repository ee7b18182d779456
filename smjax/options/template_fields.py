"""The templates' state functions (and the hierarchy's ``success``) read off environment states.

``HierarchyRunner.tick`` asks these, per option, what a state means: whether each
template is satisfied or failed (its run stops), the side-cost shaping a template's
learner gets, and the root's task success of an ending episode. ``per_option`` reads one
environment (unbatched); the others take batched states (leading axis B). Pure functions
of the templates and the environment parameters: no runner, no learner.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp


def per_option(templates, env_params, state, field: str, root, dtype) -> jax.Array:
    """[O]: ``root`` for the root option, then each template's ``field`` on ``state``
    (``root`` too where a template leaves that optional field unset)."""
    fns = [getattr(t, field) for t in templates]
    vals = [root] + [root if fn is None else fn(state, env_params) for fn in fns]
    return jnp.stack([jnp.asarray(v, dtype).reshape(()) for v in vals])


def stop_conditions(templates, env_params, state) -> tuple[jax.Array, jax.Array]:
    """(satisfied, satisfied or failed), both [B, O], in the stepped state."""
    sat = jax.vmap(lambda s: per_option(templates, env_params, s, "satisfied", False, bool))(state)
    if any(t.failed is not None for t in templates):
        failed = jax.vmap(lambda s: per_option(templates, env_params, s, "failed", False, bool))
        return sat, sat | failed(state)
    return sat, sat


def side_costs(templates, env_params, before, after, on, weight):
    """Every template's extra reward [B, O] ``c(s) - c(s')`` for its ``side_cost`` c, times
    ``weight`` (``Controls.side_cost``), where it is ``on`` the stack (0 for the root, and
    0.0 altogether where no weight is given or no template has a side cost).

    Undiscounted on purpose: a cost is charged when it is incurred (a unit picked up) and
    given back when it goes (a unit consumed), so what an option already holds when it is
    called costs nothing while it waits. The discounted form ``c(s) - gamma * c(s')`` would
    pay ``(1 - gamma) * c`` every tick for holding c: over a run, up to c in all, so an
    option called while holding weight x 0.1 x (items) >= 1 would earn more by never
    finishing."""
    if weight is None or not any(t.side_cost is not None for t in templates):
        return 0.0
    cost = jax.vmap(lambda s: per_option(templates, env_params, s, "side_cost", 0.0, jnp.float32))
    c0 = cost(before)
    c1 = cost(after)
    weight = jnp.asarray(weight, jnp.float32)
    template = (jnp.arange(len(templates) + 1) > 0)[None, :]  # the root is option 0
    return jnp.where(on & template, weight * (c0 - c1), 0.0)


def task_success(success, env_params, state, info: dict) -> jax.Array | None:
    """[B] float: the root's success of episodes ending in ``state`` (batched): the
    hierarchy's declared ``success(state, params)`` (``Hierarchy.success``), else the
    environment's ``info["success"]`` (e.g. Fetch's fraction of blocks placed); None where
    neither exists (the episode return is the success then)."""
    if success is not None:
        value = jax.vmap(success, (0, None))(state, env_params)
        return jnp.asarray(value, jnp.float32).reshape(-1)  # scalar or [1] per state
    if "success" in info:
        return jnp.asarray(info["success"], jnp.float32)
    return None
