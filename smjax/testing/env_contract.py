"""``check_env``: the environment contract, checked on a short random rollout.

Compile time dominates on a CPU, so the checks share three programs: the eager
(unjitted) reset and step; one jitted single-environment program evaluating ``reset``,
``step`` and ``step_env``; and one jitted batched rollout whose ``params`` is an argument
(a shorter ``max_steps`` reuses it, and so does ``check_hierarchy`` at the same sizes).
"""
from __future__ import annotations

import math
import weakref
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core import spaces
from smjax.core.layout import check_layout
from smjax.testing.compare import (
    ATOL, RTOL, assert_trees_close, fail, index, tolerances, trees_mismatch,
)


# Rollout programs by environment, so check_hierarchy after check_env (same sizes) reuses
# the compiled rollout; weak keys let environments (and their programs) be collected.
_ROLLOUTS: "weakref.WeakKeyDictionary[Any, dict]" = weakref.WeakKeyDictionary()


def make_rollout(env, action_space: spaces.Space, num_envs: int, steps: int) -> Callable:
    """jit(key, params) -> ((reset obs, reset state), (states, actions, keys, step outputs)).

    ``states[t]`` is the batch *before* step t; every leaf is [steps, num_envs, ...].
    """
    cache_key = (repr(action_space), num_envs, steps)
    try:
        return _ROLLOUTS[env][cache_key]
    except (KeyError, TypeError):  # TypeError: an env that cannot be weakly referenced
        pass
    batched_reset = jax.vmap(env.reset, in_axes=(0, None))
    batched_step = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def run(key, params):
        key_reset, key_run = jax.random.split(key)
        obs, state = batched_reset(jax.random.split(key_reset, num_envs), params)

        def body(state, k):
            key_act, key_step = jax.random.split(k)
            actions = jax.vmap(action_space.sample)(jax.random.split(key_act, num_envs))
            step_keys = jax.random.split(key_step, num_envs)
            out = batched_step(step_keys, state, actions, params)
            return out[1], (state, actions, step_keys, out)

        _, traj = jax.lax.scan(body, state, jax.random.split(key_run, steps))
        return (obs, state), traj

    program = jax.jit(run)
    try:
        _ROLLOUTS.setdefault(env, {})[cache_key] = program
    except TypeError:
        pass
    return program


def _make_one_env(env) -> Callable:
    """jit: one environment's ``reset(reset_key)`` and ``step``, and step_env's observation.

    One program for every single-environment check (one compile instead of three).
    ``ended`` is step_env's observation for the first half of ``split(key)``, the key the
    base class's ``step`` hands it (XLA shares that computation with ``step``'s own).
    """
    def one(reset_key, key, state, action, params):
        ended = env.step_env(jax.random.split(key)[0], state, action, params)[0]
        return {"reset": env.reset(reset_key, params), "ended": ended,
                "step": env.step(key, state, action, params)}

    return jax.jit(one)


def compared_state(env, state: Any) -> Any:
    """``state`` cut to what two programs must agree on (``Environment.contract_state``;
    the whole state for an environment without it)."""
    view = getattr(env, "contract_state", None)
    return state if view is None else view(state)


def compared(env, out: tuple) -> tuple:
    """``(obs, state, ...)`` with its state as ``compared_state`` cuts it."""
    return (out[0], compared_state(env, out[1]), *out[2:])


def env_tolerances(env, rtol: float | None, atol: float | None) -> tuple[float, float]:
    """The tolerances given, else those the environment declares, else the defaults."""
    declared = getattr(env, "contract_tolerances", None) or (RTOL, ATOL)
    return (declared[0] if rtol is None else rtol, declared[1] if atol is None else atol)


def short_params(params: Any, steps: int) -> Any | None:
    """params with ``max_steps`` cut to ``steps // 4`` so episodes end in a rollout."""
    if not hasattr(params, "max_steps") or not hasattr(params, "replace"):
        return None
    old = params.max_steps
    short = max(1, steps // 4)
    return params.replace(max_steps=jnp.asarray(short, jnp.asarray(old).dtype))


# ---- the checks ------------------------------------------------------------------------
def check_spaces(env, params, who: str) -> tuple[spaces.Space, spaces.Space]:
    act, obs = env.action_space(params), env.observation_space(params)
    for name, space in (("action_space", act), ("observation_space", obs)):
        if not isinstance(space, spaces.Space):
            fail("spaces", who, f"{name} returned {type(space).__name__}, not a smjax space")
    try:  # the grids a conv torso would read lie inside the flattened observation
        check_layout(env.observation_layout(params), math.prod(obs.shape))
    except ValueError as err:
        fail("spaces", who, f"observation_layout: {err}")
    return act, obs


def check_jit_eager(env, params, key, act_space, one, who: str) -> None:
    """Unjitted (op by op) and jitted reset/step agree for two steps."""
    key_reset, key = jax.random.split(key)
    eager = env.reset(key_reset, params)
    state = eager[1]
    for t in range(2):
        key, key_act, key_step = jax.random.split(key, 3)
        action = act_space.sample(key_act)
        jitted = one(key_reset, key_step, state, action, params)
        if t == 0:
            assert_trees_close(compared(env, jitted["reset"]), compared(env, eager),
                               prop="jit == eager", who=who, where="reset")
        eager = env.step(key_step, state, action, params)
        assert_trees_close(compared(env, jitted["step"]), compared(env, eager),
                           prop="jit == eager", who=who, where=f"step {t}")
        state = eager[1]


def check_step_outputs(traj, obs_space: spaces.Space, who: str) -> None:
    obs, _, reward, terminated, truncated, info = traj[3]
    lead = reward.shape
    if len(lead) != 2:
        fail("step outputs", who, f"reward has shape {reward.shape[2:]} per env, expected ()")
    want = {"obs": (lead + tuple(obs_space.shape), jnp.dtype(obs_space.dtype)),
            "terminated": (lead, jnp.dtype(bool)), "truncated": (lead, jnp.dtype(bool))}
    got = {"obs": obs, "terminated": terminated, "truncated": truncated}
    for name, (shape, dtype) in want.items():
        x = got[name]
        if x.shape != shape or x.dtype != dtype:
            fail("step outputs", who, f"{name} has shape {x.shape[2:]} dtype {x.dtype} per env, "
                 f"expected shape {shape[2:]} dtype {dtype}")
    if not jnp.issubdtype(reward.dtype, jnp.floating):
        fail("step outputs", who, f"reward dtype {reward.dtype} is not floating")
    if not isinstance(info, dict) or "final_observation" not in info:
        fail("final_observation", who, 'step returned no info["final_observation"]')


def check_observations(reset_obs, traj, obs_space: spaces.Space, who: str) -> None:
    """Every observation of the rollout is finite and inside the observation space."""
    obs, *_, info = traj[3]
    batches = {"reset": reset_obs[None], "step": obs,
               'info["final_observation"]': info["final_observation"]}
    contains = jax.vmap(jax.vmap(obs_space.contains))  # eager: a few ops, nothing to compile
    for name, o in batches.items():
        o = jnp.asarray(o)
        if jnp.issubdtype(o.dtype, jnp.inexact):
            finite = np.asarray(jnp.isfinite(o).reshape(o.shape[:2] + (-1,)).all(-1))
            if not finite.all():
                t, i = np.argwhere(~finite)[0]
                fail("observation finite", who,
                     f"{name} observation at step {t}, env {i} has non-finite values")
        inside = np.asarray(contains(o))
        if not inside.all():
            t, i = np.argwhere(~inside)[0]
            bad = np.asarray(o[t, i])
            fail("observation in space", who, f"{name} observation at step {t}, env {i} lies "
                 f"outside {obs_space!r} (min {bad.min()}, max {bad.max()})")


def check_rewards(traj, who: str) -> None:
    """Every reward of the rollout is finite: a NaN would reach the learner's update."""
    reward = np.asarray(traj[3][2])
    finite = np.isfinite(reward)
    if not finite.all():
        t, i = np.argwhere(~finite)[0]
        fail("reward finite", who, f"reward at step {t}, env {i} is {reward[t, i]} "
             f"({int((~finite).sum())} of {finite.size} rewards are non-finite)")


def check_vmap_loop(env, params, key_roll, rollout_out, one, times, who: str) -> None:
    """The batched rollout, env by env, equals single-environment reset and steps."""
    (reset_obs, reset_state), (states, actions, keys, out) = rollout_out
    num_envs = actions.shape[1]
    reset_keys = jax.random.split(jax.random.split(key_roll)[0], num_envs)
    for t in times:
        for i in range(num_envs):
            single = one(reset_keys[i], keys[t, i], index(states, t, i), actions[t, i], params)
            if t == times[0]:
                assert_trees_close(compared(env, single["reset"]),
                                   compared(env, index((reset_obs, reset_state), i)),
                                   prop="vmap == loop", who=who, where=f"reset, env {i}")
            assert_trees_close(compared(env, single["step"]), compared(env, index(out, t, i)),
                               prop="vmap == loop", who=who, where=f"step {t}, env {i}")


def check_auto_reset(env, params, traj, one, who: str, max_checks: int = 4) -> None:
    """Ended episodes restart from reset_env; final_observation is step_env's observation."""
    states, actions, keys, (obs, state, _, terminated, truncated, info) = traj
    done = np.asarray(terminated | truncated)
    final = info["final_observation"]
    for t, i in np.argwhere(~done)[:max_checks]:
        assert_trees_close(index(final, t, i), index(obs, t, i), prop="final_observation",
                           who=who, where=f"step {t}, env {i} (episode goes on): it differs "
                           f"from the returned observation")
    whole_key_step = None
    for t, i in np.argwhere(done)[:max_checks]:
        key, s, a = keys[t, i], index(states, t, i), actions[t, i]
        single = one(jax.random.split(key)[1], key, s, a, params)
        assert_trees_close(compared(env, (index(obs, t, i), index(state, t, i))),
                           compared(env, single["reset"]),
                           prop="auto-reset", who=who, where=f"step {t}, env {i} (episode "
                           f"ended): the returned observation/state is not reset_env's")
        got = index(final, t, i)
        why = trees_mismatch(got, single["ended"])
        if why is not None:
            # An environment whose reset ignores its key (football) may hand step_env the
            # whole key; compiled only when needed.
            whole_key_step = whole_key_step or jax.jit(env.step_env)
            if trees_mismatch(got, whole_key_step(key, s, a, params)[0]) is not None:
                fail("final_observation", who, f"step {t}, env {i} (episode ended): it is "
                     f"not step_env's observation: {why}")


def check_render(env, params, state, who: str) -> None:
    try:
        image = env.render(state, params)
    except NotImplementedError:  # rendering is optional
        return
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[-1] != 3:
        fail("render", who, f"render returned {image.dtype} {image.shape}, expected uint8 "
             f"(H, W, 3)")


def check_describe(env, params, state, who: str) -> None:
    """Optional too, but needs no graphics backend, so ``render=False`` does not skip it."""
    text = env.describe(state, params)  # None: the environment has no text form
    if text is not None and (not isinstance(text, str) or not text.strip()):
        fail("describe", who, f"describe returned {text!r}, expected a non-empty str or None")


def _spread(steps: int, count: int = 3) -> list[int]:
    return sorted({int(t) for t in np.linspace(0, steps - 1, min(steps, count))})


def _any_done(traj) -> bool:
    return bool(np.any(np.asarray(traj[3][3] | traj[3][4])))


def check_env(env, params: Any = None, *, num_envs: int = 8, steps: int = 64,
              key: jax.Array | None = None, render: bool = True, rtol: float | None = None,
              atol: float | None = None) -> None:
    """Check that ``env`` meets the smjax environment contract (see ``smjax.testing``).

    Plays ``num_envs`` environments for ``steps`` random steps. If no episode ends and
    ``params`` has a ``max_steps`` field, the auto-reset check plays again with
    ``max_steps = steps // 4``; other environments need params (or ``steps``) under which
    episodes end. ``rtol``/``atol`` bound float differences between two programs (jit vs
    eager, vmap vs loop); None: the environment's ``contract_tolerances``, else ``RTOL``/
    ``ATOL``. Raises ``AssertionError`` whose message starts with the property.
    """
    with tolerances(*env_tolerances(env, rtol, atol)):
        _check_env(env, params, num_envs, steps, key, render)


def _check_env(env, params, num_envs: int, steps: int, key, render: bool) -> None:
    params = env.default_params if params is None else params
    key = jax.random.PRNGKey(0) if key is None else key
    who = getattr(env, "name", type(env).__name__)
    act_space, obs_space = check_spaces(env, params, who)
    one = _make_one_env(env)
    key_eager, key_roll = jax.random.split(key)
    check_jit_eager(env, params, key_eager, act_space, one, who)

    rollout = make_rollout(env, act_space, num_envs, steps)
    first = rollout(key_roll, params)
    (reset_obs, _), traj = first
    check_step_outputs(traj, obs_space, who)
    assert_trees_close(rollout(key_roll, params), first, prop="determinism", who=who,
                       exact=True, where="two rollouts with the same key")
    check_observations(reset_obs, traj, obs_space, who)
    check_rewards(traj, who)
    check_vmap_loop(env, params, key_roll, first, one, _spread(steps), who)
    if not _any_done(traj):
        short = short_params(params, steps)
        if short is None:
            fail("auto-reset", who, f"no episode ended in {steps} random steps of {num_envs} "
                 f"environments; pass params (or steps) under which episodes end")
        (reset_obs, _), traj = rollout(key_roll, short)
        if not _any_done(traj):
            fail("auto-reset", who, f"no episode ended in {steps} steps, even with "
                 f"max_steps={max(1, steps // 4)}")
        check_observations(reset_obs, traj, obs_space, who)
        check_rewards(traj, who)
        params = short
    check_auto_reset(env, params, traj, one, who)
    if render:
        check_render(env, params, index(traj[0], 0, 0), who)
    check_describe(env, params, index(traj[0], 0, 0), who)
