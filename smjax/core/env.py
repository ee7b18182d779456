"""The environment protocol every smjax environment implements (gymnax 1.0 lineage).

An environment is a stateless object whose methods are pure functions of explicit
state and params, so they jit and vmap. Subclasses implement ``initial_state`` (or
``reset_env``), ``step_env`` (no auto-reset), ``get_obs`` and the spaces; the base class
adds ``reset`` and the auto-resetting six-value ``step``:

    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)

When an episode ends inside ``step`` the returned ``obs``/``state`` already belong to
the next episode and ``info["final_observation"]`` holds the observation it ended on.
Auto-reset lives here and only here: no environment overrides ``step``.

Under ``vmap`` both sides of the reset select run in every step, so a reset is paid on
every step of every environment. Two hooks keep that cheap:

* ``initial_state(key, params)``: the state an episode starts from, without its
  observation. An environment that implements it gets ``reset_env`` for free, and
  ``step`` selects the *state* first (step_env's or the fresh one) and observes the
  selected one once, instead of observing both and selecting an observation. Where the
  observation is the expensive part (Craft's 1586 features) this halves the work of a
  step; a caller that ignores ``info["final_observation"]`` lets XLA drop step_env's own
  observation too. It requires that step_env's observation is ``get_obs`` of the state
  it returns (so that ``obs`` is exactly what the generic path would give).
* ``reset_ignores_key``: True where every episode starts from the same state (football's
  kick-off). ``step`` then hands its key to ``step_env`` whole instead of splitting it
  (a threefry call per step saved).

Environments without ``initial_state`` (adapters, small test environments) take the
generic path: ``reset_env`` and ``step_env`` each observe, and the observation is selected.
The option machinery uses ``step_env``/``reset_env`` directly, because it decides
itself when an episode (of a learner) ends.
"""
from __future__ import annotations

from typing import Any, Generic, TypeVar

import jax
import jax.numpy as jnp

from smjax.core import spaces

TEnvState = TypeVar("TEnvState")
TEnvParams = TypeVar("TEnvParams")

StepResult = tuple[jax.Array, Any, jax.Array, jax.Array, jax.Array, dict]


def select_tree(pred: jax.Array, on_true: Any, on_false: Any) -> Any:
    """Leaf-wise ``jnp.where`` over two pytrees of equal structure (pred is a scalar bool)."""
    return jax.tree.map(lambda a, b: jnp.where(pred, a, b), on_true, on_false)


def over_seeds(fn, one_after_another: bool, in_axes: int | tuple = 0):
    """``fn`` of one seed over arguments with a leading seed axis (``in_axes`` as ``vmap``'s:
    0, or per argument 0 or None for one shared by every seed): side by side (``vmap``), or
    one seed after another (``lax.map``), where a ``lax.cond`` branches for that seed alone
    and a loop ends with its own work: right where compute is serial (one CPU device)."""
    if not one_after_another:
        return jax.vmap(fn, in_axes=in_axes)

    def mapped(*args):
        axes = in_axes if isinstance(in_axes, tuple) else (in_axes,) * len(args)

        def one(per_seed):
            values = iter(per_seed)
            return fn(*[next(values) if axis == 0 else x for x, axis in zip(args, axes)])

        return jax.lax.map(one, [x for x, axis in zip(args, axes) if axis == 0])

    return mapped


class Environment(Generic[TEnvState, TEnvParams]):
    """Base class of smjax environments."""

    #: ``ENV/TASK`` name this instance was made for (set by the registry).
    name: str = "unnamed"
    #: The task's per-episode success (a hierarchy's declared ``success``, else
    #: ``info["success"]``, else the episode return) always
    #: lies in [0, 1]. Lets the trainer stop a level's gate as soon as its outcome is
    #: certain; leave False where returns can leave [0, 1] (e.g. goal differences).
    success_in_unit_interval: bool = False
    #: That success has no scale a threshold could mean (an adapted gymnax environment's
    #: return: CartPole's is tens): a root level never ends at a threshold but spends its
    #: budget, unless the hierarchy declares a success of its own.
    success_unbounded: bool = False
    #: ``initial_state``/``reset_env`` ignore their key (every episode starts from the same
    #: state): ``step`` then passes its key to ``step_env`` unsplit (see the module docstring).
    reset_ignores_key: bool = False
    #: ``(rtol, atol)`` within which floats of two programs computing the same step (jit vs
    #: eager, vmap vs loop) agree; None: ``smjax.testing``'s defaults. A physics solver run
    #: for a few iterations leaves larger differences (Fetch's velocities: ~1e-5).
    contract_tolerances: tuple[float, float] | None = None

    def contract_state(self, state: TEnvState) -> Any:
        """The part of ``state`` on which two programs computing the same step (jit vs
        eager, vmap vs loop) must agree, for ``smjax.testing``: all of it unless an
        environment holds quantities that amplify float32 rounding (a physics engine's
        forces and accelerations) beside the state that determines them."""
        return state

    # ---- to implement -------------------------------------------------
    @property
    def default_params(self) -> TEnvParams:
        raise NotImplementedError

    def initial_state(self, key: jax.Array, params: TEnvParams) -> TEnvState:
        """The state an episode starts from, without its observation (optional hook).

        Implement this *or* ``reset_env``; with it, ``reset_env`` is ``get_obs`` of this
        state and ``step``'s auto-reset observes only the state it keeps.
        """
        raise NotImplementedError

    def reset_env(self, key: jax.Array, params: TEnvParams) -> tuple[jax.Array, TEnvState]:
        """(observation, state) an episode starts from; default: ``initial_state``."""
        state = self.initial_state(key, params)
        return self.get_obs(state, params), state

    def step_env(
        self, key: jax.Array, state: TEnvState, action: jax.Array, params: TEnvParams
    ) -> StepResult:
        """One step without auto-reset: (obs, state, reward, terminated, truncated, info)."""
        raise NotImplementedError

    def get_obs(self, state: TEnvState, params: TEnvParams) -> jax.Array:
        raise NotImplementedError

    def action_space(self, params: TEnvParams | None = None) -> spaces.Space:
        raise NotImplementedError

    def observation_space(self, params: TEnvParams | None = None) -> spaces.Space:
        raise NotImplementedError

    def render(self, state: TEnvState, params: TEnvParams | None = None):
        """RGB uint8 image (H, W, 3) of one (unbatched) state."""
        raise NotImplementedError

    def describe(self, state: TEnvState, params: TEnvParams | None = None) -> str | None:
        """One (unbatched) state as text, for traces of episodes (``benchmarks/
        diagnose_hierarchy.py --trace``); None where the environment has no text form."""
        return None

    def observation_layout(self, params: TEnvParams | None = None) -> tuple:
        """The grids of the flattened observation (``smjax.core.layout.Grid``), for
        learners with a convolutional torso; none by default."""
        return ()

    def templates(self) -> dict:
        """Option templates this environment offers, by name (may be empty)."""
        return {}

    def hierarchies(self) -> dict:
        """Named hierarchies (``smjax.options.Hierarchy``) over ``templates()``, the default
        first (a run that names none trains the first). The flat method trains the chosen
        one's flattening (``Hierarchy.flattened``)."""
        return {}

    @property
    def primitive_action_names(self) -> tuple[str, ...]:
        """Names of the discrete primitive actions (empty for continuous actions)."""
        space = self.action_space(self.default_params)
        if isinstance(space, spaces.Discrete) and space.shape == ():
            return tuple(f"action_{i}" for i in range(space.n))
        return ()

    # ---- provided -------------------------------------------------------
    def reset(self, key: jax.Array, params: TEnvParams | None = None) -> tuple[jax.Array, TEnvState]:
        if params is None:
            params = self.default_params
        return self.reset_env(key, params)

    def step(
        self,
        key: jax.Array,
        state: TEnvState,
        action: jax.Array,
        params: TEnvParams | None = None,
    ) -> StepResult:
        """Step with auto-reset; the pre-reset observation is in ``info["final_observation"]``.

        The one auto-reset of every environment (see the module docstring for the hooks
        that make it cheap).
        """
        if params is None:
            params = self.default_params
        if self.reset_ignores_key:
            key_step = key_reset = key
        else:
            key_step, key_reset = jax.random.split(key)
        obs_st, state_st, reward, terminated, truncated, info = self.step_env(
            key_step, state, action, params
        )
        done = jnp.logical_or(terminated, truncated)
        if self.has_initial_state:
            state = select_tree(done, self.initial_state(key_reset, params), state_st)
            obs = self.get_obs(state, params)
        else:
            obs_re, state_re = self.reset_env(key_reset, params)
            state = select_tree(done, state_re, state_st)
            obs = select_tree(done, obs_re, obs_st)
        info = dict(info)
        info["final_observation"] = obs_st
        return obs, state, reward, terminated, truncated, info

    @property
    def has_initial_state(self) -> bool:
        """The class implements the ``initial_state`` hook."""
        return type(self).initial_state is not Environment.initial_state

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"
