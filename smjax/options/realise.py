"""Realising a tick's decision as one environment action (and, for a teleport, a jump).

The decision cascade (``smjax.options.phases.decide``) fixes per environment a primitive
action, a scripted template (its controller picks the action) or a teleported template
(its teleport jumps the state and gives the action). Templates whose realisations share
one function form a *family*: one vmapped call per family realises all its members, each
environment with its member's data, instead of one call per template.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.env import select_tree
from smjax.options.template import Parametric


def primitive_action(primitive: jax.Array, action_shape: tuple, action_dtype) -> jax.Array:
    """[B, *action_shape]: each environment's primitive action id as the environment's
    action (broadcast over its shape; controllers and teleports overwrite it later)."""
    B = primitive.shape[0]
    return jnp.broadcast_to(
        primitive.reshape((B,) + (1,) * len(action_shape)), (B,) + action_shape
    ).astype(action_dtype)


def run_family(fams: list["Family"], key: jax.Array, state, chosen: jax.Array, action: jax.Array,
               env_params, action_dtype, *, controls: bool):
    """Realise the template ``chosen[b]`` (option id, -1 for none) of each environment.

    One vmapped call per family: a family's data is gathered per environment for the
    member it runs. Controllers return an action; teleports a (state, action) pair.
    Every family runs on every environment (the unchosen results are discarded): under
    vmap there is no cheaper way to run a different function per environment.
    """
    B = chosen.shape[0]
    safe = jnp.maximum(chosen, 0)
    for i, fam in enumerate(fams):
        keys = jax.random.split(jax.random.fold_in(key, i), B)
        member = jnp.asarray(fam.member_of)[safe]
        hit = (chosen >= 0) & jnp.asarray(fam.is_member)[safe]
        data = jax.tree.map(lambda d: jnp.asarray(d)[member], fam.data)
        out = jax.vmap(fam.fn, (0, 0, None, 0))(keys, state, env_params, data)
        if controls:
            new_action = out
        else:
            jumped, new_action = out
            state = jax.vmap(select_tree)(hit, jumped, state)
        new_action = jnp.asarray(new_action, action_dtype).reshape(action.shape)
        action = jnp.where(hit.reshape((B,) + (1,) * (action.ndim - 1)), new_action, action)
    return action if controls else (state, action)


@dataclass(frozen=True)
class Family:
    fn: Any
    data: Any             # stacked member data, leading axis = member
    member_of: np.ndarray  # [num_options] -> member index (0 where not a member)
    is_member: np.ndarray  # [num_options] bool


def families(realisations) -> list[Family]:
    """Group templates' teleports (or controllers) into families sharing one function.

    ``Parametric`` realisations with the same ``fn`` form one family; any other callable
    is a family of one (with no data). Option ids are template index + 1 (0 is the root).
    """
    groups: dict[int, list] = {}
    order: list[int] = []
    for j, real in enumerate(realisations, start=1):
        if real is None:
            continue
        fn = real.fn if isinstance(real, Parametric) else real
        if id(fn) not in groups:
            groups[id(fn)] = []
            order.append(id(fn))
        groups[id(fn)].append((j, real))
    out = []
    n = len(realisations) + 1
    for gid in order:
        members = groups[gid]
        first = members[0][1]
        member_of, is_member = np.zeros(n, np.int32), np.zeros(n, bool)
        for m, (j, _) in enumerate(members):
            member_of[j], is_member[j] = m, True
        if isinstance(first, Parametric):
            data = jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]),
                                *[r.data for _, r in members])
            fn = first.fn
        else:
            data, fn = np.zeros((1,), np.int32), drop_data(first)
        out.append(Family(fn, data, member_of, is_member))
    return out


def drop_data(fn):
    def call(key, state, params, _data):
        return fn(key, state, params)
    return call
