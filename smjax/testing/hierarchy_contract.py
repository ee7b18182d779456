"""``check_hierarchy``: every template of a hierarchy, on states reached by random play.

Each template is evaluated by one function of (key, state) returning everything it
defines (initiation, satisfied, failed, the teleport's jump, action and outcome, the
controller's action); that one function is compiled twice, vmapped and single, so a
hierarchy costs two compiles per template.

Random play rarely reaches the states where higher templates are initiable (a door
needs its key), so templates are checked deepest first and each teleport's outcomes
replace about half of the states where it ran: a parent is then checked on the states
its children's teleports lead to. A teleport still initiable in none of the states
fails the check (``teleport outcome``), since nothing would have checked it.
"""
from __future__ import annotations

import zlib
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.options.hierarchy import Hierarchy
from smjax.options.template import OptionTemplate
from smjax.testing.compare import (
    all_equal, assert_trees_close, fail, index, tolerances,
)
from smjax.testing.env_contract import compared_state, env_tolerances, make_rollout

PREDICATES = ("initiation", "satisfied", "failed")


def random_states(env, params, key, num_envs: int, steps: int, count: int) -> Any:
    """``count`` states spread over a random-play rollout (leading axis ``count``)."""
    rollout = make_rollout(env, env.action_space(params), num_envs, steps)
    _, (states, *_) = rollout(key, params)
    # explicit size, not -1: MJX states hold zero-size arrays
    flat = jax.tree.map(lambda x: x.reshape((steps * num_envs,) + x.shape[2:]), states)
    picks = np.linspace(0, steps * num_envs - 1, min(count, steps * num_envs)).astype(int)
    return jax.tree.map(lambda x: x[picks], flat)


def _template_fn(env, tpl: OptionTemplate, params) -> Callable:
    """(key, state) -> dict of everything the template computes in that state."""
    def evaluate(key, state):
        out = {name: getattr(tpl, name)(state, params) for name in PREDICATES
               if getattr(tpl, name) is not None}
        key_tp, key_step = jax.random.split(key)
        if tpl.teleport is not None:
            jumped, action = tpl.teleport(key_tp, state, params)
            outcome = env.step_env(key_step, jumped, action, params)[1]
            out["teleport_state"] = jumped
            out["teleport_action"] = jnp.asarray(action)
            # The promise may hold after the jump itself (Craft adds a crafted item) or
            # only after the named action (Craft picks a primitive up with USE).
            out["teleport_reached"] = tpl.satisfied(jumped, params) | tpl.satisfied(outcome, params)
            # A teleport that leaves the state unchanged declares itself impossible here
            # (Craft: nothing of the target kind has an empty neighbour).
            out["teleport_moved"] = ~all_equal(jumped, state)
            out["teleport_outcome"] = outcome
        if tpl.controller is not None:
            out["controller_action"] = jnp.asarray(tpl.controller(key_tp, state, params))
        return out

    return evaluate


def _compared(env, out: dict) -> dict:
    """``out`` with its states cut to what two programs must agree on (as check_env)."""
    return {k: compared_state(env, v) if k in ("teleport_state", "teleport_outcome") else v
            for k, v in out.items()}


def _check_outputs(out: dict, count: int, act_shape: tuple, who: str) -> None:
    for name in PREDICATES:
        if name in out and (out[name].shape != (count,) or out[name].dtype != jnp.bool_):
            fail("template output", who, f"{name} returned shape {out[name].shape[1:]} dtype "
                 f"{out[name].dtype} per state, expected a bool scalar")
    for name in ("teleport_action", "controller_action"):
        if name in out and out[name].shape[1:] != act_shape:
            fail(f"{name.split('_')[0]} action", who, f"action of shape {out[name].shape[1:]}, "
                 f"expected the action space's {act_shape}")


def _check_actions(out: dict, act_space, who: str) -> None:
    contains = jax.vmap(act_space.contains)
    if "teleport_action" in out:
        bad = np.argwhere(np.asarray(out["teleport_moved"] & ~contains(out["teleport_action"])))
        if bad.size:
            i = int(bad[0, 0])
            fail("teleport action", who, f"state {i}: action "
                 f"{np.asarray(out['teleport_action'][i])} lies outside {act_space!r}")
    if "controller_action" in out:
        bad = np.argwhere(~np.asarray(contains(out["controller_action"])))
        if bad.size:
            i = int(bad[0, 0])
            fail("controller action", who, f"state {i}: action "
                 f"{np.asarray(out['controller_action'][i])} lies outside {act_space!r}")


def _check_teleport_outcome(out: dict, who: str) -> None:
    if "teleport_reached" not in out:
        return
    initiable = np.asarray(out["initiation"])
    ran = initiable & np.asarray(out["teleport_moved"])
    if not ran.any():
        fail("teleport outcome", who, f"not checked: the template is initiable (with a teleport "
             f"that moves the state) in 0 of {len(initiable)} states, from random play and the "
             f"hierarchy's other teleports; raise num_states/steps, or pass params or a key "
             f"under which it is initiable")
    bad = np.argwhere(initiable & np.asarray(out["teleport_moved"] & ~out["teleport_reached"]))
    if bad.size:
        fail("teleport outcome", who, f"state {int(bad[0, 0])} ({len(bad)} of {len(initiable)} "
             f"states): initiable and teleported, but the template is satisfied neither after "
             f"the jump nor after its action")


def check_template(env, params, tpl: OptionTemplate, states, key, who: str,
                   loop_states: int = 4) -> dict:
    """One template on a batch of states: jit+vmap == loop, outputs, actions, outcomes.
    Returns everything it computed per state (``_template_fn``'s dict, batched)."""
    count = jax.tree.leaves(states)[0].shape[0]
    keys = jax.random.split(key, count)
    evaluate = _template_fn(env, tpl, params)
    out = jax.jit(jax.vmap(evaluate))(keys, states)
    act_space = env.action_space(params)
    _check_outputs(out, count, tuple(act_space.shape), who)
    one = jax.jit(evaluate)
    for i in range(min(loop_states, count)):
        assert_trees_close(_compared(env, one(keys[i], index(states, i))),
                           _compared(env, index(out, i)), prop="vmap == loop", who=who,
                           where=f"state {i}")
    _check_actions(out, act_space, who)
    _check_teleport_outcome(out, who)
    return out


def _mix_in_outcomes(states, out: dict, key) -> Any:
    """``states`` with about half of those where the teleport ran replaced by its outcome."""
    if "teleport_outcome" not in out:
        return states
    ran = out["initiation"] & out["teleport_moved"]
    take = ran & jax.random.bernoulli(key, 0.5, ran.shape)

    def pick(old, new):
        return jnp.where(take.reshape(take.shape + (1,) * (old.ndim - 1)), new, old)

    return jax.tree.map(pick, states, out["teleport_outcome"])


def check_hierarchy(env, params: Any, hierarchy: Hierarchy | str, *, num_envs: int = 8,
                    steps: int = 16, num_states: int = 32, loop_states: int = 4,
                    key: jax.Array | None = None, rtol: float | None = None,
                    atol: float | None = None) -> None:
    """Check every template of ``hierarchy`` (a Hierarchy, or a name in ``env.hierarchies()``).

    On ``num_states`` states spread over ``steps`` random steps of ``num_envs``
    environments: initiation/satisfied/failed return bools; everything a template computes
    agrees jitted+vmapped and per state (the first ``loop_states``); a teleport's outcome
    satisfies the template wherever it is initiable and the teleport moved the state, and
    there is at least one such state (templates deepest first, each checked also on its
    children's teleport outcomes); teleport and controller actions lie inside the action space. Raises
    ``AssertionError`` whose message starts with the property and names the template.
    ``rtol``/``atol`` as in ``check_env``.
    """
    params = env.default_params if params is None else params
    key = jax.random.PRNGKey(1) if key is None else key
    if isinstance(hierarchy, str):
        hierarchy = env.hierarchies()[hierarchy]
    env_name = getattr(env, "name", type(env).__name__)
    key_states, key_calls = jax.random.split(key)
    states = random_states(env, params, key_states, num_envs, steps, num_states)
    for tpl in reversed(hierarchy.template_list):  # deepest first: see the module's note
        tpl_key = jax.random.fold_in(key_calls, zlib.crc32(tpl.name.encode()))
        with tolerances(*env_tolerances(env, rtol, atol)):
            out = check_template(env, params, tpl, states, tpl_key,
                                 f"{env_name} template {tpl.name!r}", loop_states)
        states = _mix_in_outcomes(states, out, jax.random.fold_in(tpl_key, 1))
