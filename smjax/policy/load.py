"""``load_policy``: a saved policy's files -> a :class:`SavedPolicy`, every mismatch with
what it is loaded for (another task, hierarchy, learner or observation, another format,
a damaged file) refused as a ``PolicyError`` naming the path."""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.agents import make_agent
from smjax.core.registry import make
from smjax.options.hierarchy import Hierarchy
from smjax.options.runner import HierarchyRunner
from smjax.policy.artifact import (PolicyError, observation_spec, policy_folder, read_arrays,
                                   read_meta, restore_tree)
from smjax.policy.hierarchies import declared_identity, hierarchy_named
from smjax.policy.saved import PolicyParams, SavedPolicy

# settings older policies saved with the runner's (``runner_structure``)
_TICK_SETTINGS = ("gamma", "frozen_policy", "allow_teleport", "template_temperature")


def load_policy(path, *, task: str | None = None, env: tuple | None = None,
                hierarchy: Hierarchy | None = None) -> SavedPolicy:
    """The policy a run saved in ``path`` (its ``--out`` directory, or the ``policy``
    folder in it). ``task``: refuse a policy of another task. ``env``: the ``(env,
    env_params)`` pair the run was given instead of a registered task name (needed
    then). ``hierarchy``: the ``Hierarchy`` a run declared in code (needed then)."""
    meta = read_meta(path)
    where = str(policy_folder(path))
    env, env_params = _environment(meta, path, task, env)
    h = _hierarchy(meta, path, env, hierarchy)
    learner = meta["learner"]
    try:
        agent = make_agent(learner["algo"], layout=env.observation_layout(env_params),
                           **learner["agent"])
        runner = HierarchyRunner(env, env_params, h, agent, **runner_structure(meta["runner"]))
    except (TypeError, ValueError) as err:
        raise PolicyError(f"{where}: its learner cannot be built by this smjax ({err})") from None
    seen = observation_spec(runner)
    if seen != meta["observation"]:
        want = meta["observation"]
        raise PolicyError(
            f"{where}: the policy saw observations {want['dtype']}{want['shape']}, "
            f"{meta['task']} gives {seen['dtype']}{seen['shape']} here (other environment "
            f"settings, or another smjax version)")
    S, O = len(meta["seeds"]), h.num_options
    obs = jax.ShapeDtypeStruct(tuple(seen["shape"]), seen["dtype"])
    params = jax.eval_shape(lambda k, o: agent.init(k, o, h.num_actions).params,
                            jax.random.PRNGKey(0), obs)
    like = {"bank": jax.tree.map(lambda p: jax.ShapeDtypeStruct((S, O) + p.shape, p.dtype),
                                 params),
            "learned": jax.ShapeDtypeStruct((S, O), jnp.bool_),
            "eval_keys": jax.ShapeDtypeStruct((S, 2), jnp.uint32)}
    arrays = jax.tree.map(jnp.asarray, restore_tree(like, read_arrays(path, meta), where))
    return SavedPolicy(meta, runner, PolicyParams(arrays["bank"], arrays["learned"]),
                       arrays["eval_keys"])


def runner_structure(settings: dict) -> dict:
    """The runner's keyword arguments among a policy's saved runner settings: those of
    policies saved before a tick's settings came with its ``Controls`` also name the
    tick's discount and frozen-policy mode (the saved policy reads them from its
    evaluation's description now)."""
    return {k: v for k, v in settings.items() if k not in _TICK_SETTINGS}


def _environment(meta: dict, path, task: str | None, given: tuple | None):
    """(env, env_params) the policy acts in: the task it was trained on, made with the
    run's environment overrides, or the pair the caller passes for an unregistered one."""
    saved = meta["task"]
    if task is not None and task != saved:
        raise PolicyError(f"{path} holds a policy for {saved}, not {task}")
    if given is not None:
        env, params = given
        if env.name not in (saved, saved.rpartition(":")[2]):
            raise PolicyError(f"{path} holds a policy for {saved}, not {env.name}")
        return env, params
    if not meta.get("registered", True):
        raise PolicyError(f"{path} was trained on an environment passed as (env, params) "
                          f"({saved}); pass the same pair: load_policy(..., env=(env, params))")
    try:
        return make(saved, **meta.get("env_overrides", {}))
    except (KeyError, ValueError, ImportError) as err:
        text = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)
        raise PolicyError(f"{path}: its task {saved} cannot be made here ({text})") from None


def _hierarchy(meta: dict, path, env, given: Hierarchy | None) -> Hierarchy:
    """The hierarchy the policy runs, checked to have the options it was trained with."""
    declared = meta.get("hierarchy_declared")
    if declared is not None and given is None:
        raise PolicyError(f"{path} was trained with a hierarchy declared in code "
                          f"({declared['task']!r}); pass the same Hierarchy (hierarchy=...) "
                          f"to load it")
    if given is not None and (declared is None or declared_identity(given) != declared):
        raise PolicyError(f"{path} was not trained with this hierarchy")
    try:
        h = hierarchy_named(env, meta["hierarchy"], given)
    except ValueError as err:
        raise PolicyError(f"{path}: {err}") from None
    if list(h.option_names) != meta.get("options"):
        raise PolicyError(f"{path}: hierarchy {meta['hierarchy']!r} has options "
                          f"{list(h.option_names)} here, the policy was trained with "
                          f"{meta.get('options')} (another smjax version?)")
    return h
