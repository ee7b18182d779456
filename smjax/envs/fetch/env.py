"""FetchEnv: stack N blocks into a tower with a floating MJX gripper.

Action: float32[4] in [-1, 1] (``dynamics`` says what each entry does). Episodes:
truncated after ``params.max_steps`` (50 N) steps; terminated only when the simulation
diverges (the reference has no terminal state: a stacked tower must also be kept
stacked). ``info``: ``score`` = (min(0, r) + N) / N, ``is_success`` = every block within
0.04 m of its goal, ``placed`` = bool[N].

The package's modules, one job each (the same names in every environment package):
``types`` (state, params, static config, qpos accessors), ``reset`` (goal and block
sampling, the initial state), ``dynamics`` (physics step, reward, score), ``observation``,
``templates`` (option templates and hierarchies), ``render``, ``env`` (this class, its
factory ``make_fetch`` and the task registration); and
Fetch's own ``model`` (the MJCF scene), ``controllers`` (the templates' scripted
controllers), ``scripted`` (the fully scripted hierarchy) and ``brax_adapter``.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from smjax.core import spaces
from smjax.core.env import Environment
from smjax.core.overrides import INT32_MAX, parse_bool, parse_float, parse_int
from smjax.core.registry import register
from smjax.envs.fetch import dynamics, reset
from smjax.envs.fetch import model as fm
from smjax.envs.fetch.model import MAX_BLOCKS, MIN_BLOCKS, PhysicsConfig, check_num_blocks
from smjax.envs.fetch import types as st
from smjax.envs.fetch.observation import observation
from smjax.envs.fetch.types import FetchConfig, FetchParams, FetchState


class FetchEnv(Environment[FetchState, FetchParams]):
    """Fetch & Stack (see module docstring)."""

    success_in_unit_interval = True  # info["success"] is the score (min(0, r) + N) / N
    # positions and velocities of two programs (jit and eager, vmapped and single) differ
    # by up to ~1e-5 after a step's 8 substeps of a 4-iteration solver
    contract_tolerances = (1e-5, 1e-4)

    def __init__(self, config: FetchConfig = FetchConfig()):
        self.config = config
        self.num_blocks = config.num_blocks
        self.mj_model = fm.build_model(config.num_blocks, config.physics)
        self.index = fm.model_index(self.mj_model, config.num_blocks)
        self._check_layout()
        lo = np.array(fm.GRIPPER_START, np.float32)
        self._ws_low = np.asarray(
            [lo[0] - fm.WORKSPACE_XY, lo[1] - fm.WORKSPACE_XY, fm.WORKSPACE_Z[0]], np.float32)
        self._ws_high = np.asarray(
            [lo[0] + fm.WORKSPACE_XY, lo[1] + fm.WORKSPACE_XY, fm.WORKSPACE_Z[1]], np.float32)

    # The MJX model and its first data are made on first use, not with the env: putting
    # them on the device runs XLA programs, and making a task must run none (every refusal
    # that follows comes before any compile). Made eagerly even when first used inside a
    # traced function, so that no tracer is kept.
    @functools.cached_property
    def mjx_model(self) -> mjx.Model:
        with jax.ensure_compile_time_eval():
            return mjx.put_model(self.mj_model, impl="jax")

    @functools.cached_property
    def _data0(self) -> mjx.Data:
        with jax.ensure_compile_time_eval():
            return mjx.make_data(self.mjx_model, impl="jax")

    def contract_state(self, state: FetchState) -> FetchState:
        # The state MuJoCo integrates; the rest of mjx.Data is computed from it each step.
        # Those derived forces and accelerations scale float32 rounding in positions by the
        # servos' stiffness (gain 30000: 1e-8 m of difference is 3e-4 N), and qacc_warmstart
        # only seeds the solver, so two programs agree on them to ~2e-3, not to rounding.
        d = state.data
        return state.replace(data={"qpos": d.qpos, "qvel": d.qvel, "act": d.act, "ctrl": d.ctrl,
                                   "time": d.time, "mocap_pos": d.mocap_pos,
                                   "mocap_quat": d.mocap_quat})

    def _check_layout(self) -> None:
        # types.py's accessors hard-code the qpos layout; fail loudly if the model drifts.
        idx = self.index
        expected = (st.GRIPPER_QPOS, st.GRIPPER_QVEL, (st.FINGER_QPOS, st.FINGER_QPOS + 1),
                    (st.FINGER_QVEL, st.FINGER_QVEL + 1),
                    tuple(st.BLOCK_QPOS0 + 7 * i for i in range(self.num_blocks)),
                    tuple(st.BLOCK_QVEL0 + 6 * i for i in range(self.num_blocks)))
        got = (idx.gripper_qpos, idx.gripper_qvel, idx.finger_qpos, idx.finger_qvel,
               idx.block_qpos, idx.block_qvel)
        if expected != got:
            raise RuntimeError(f"fetch model layout {got} differs from accessors {expected}")

    # ---- contract ------------------------------------------------------------
    @property
    def default_params(self) -> FetchParams:
        return FetchParams(max_steps=np.asarray(50 * self.num_blocks, np.int32))

    def action_space(self, params: FetchParams | None = None) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (4,), jnp.float32)

    def observation_space(self, params: FetchParams | None = None) -> spaces.Box:
        return spaces.Box(-jnp.inf, jnp.inf, (self.config.obs_size,), jnp.float32)

    def get_obs(self, state: FetchState, params: FetchParams | None = None) -> jax.Array:
        return observation(state, self.config)

    def initial_state(self, key: jax.Array, params: FetchParams) -> FetchState:
        return reset.initial_state(key, params, self.config, self.mjx_model, self._data0)

    def step_env(self, key: jax.Array, state: FetchState, action: jax.Array,
                 params: FetchParams):
        new_state, r, terminated, truncated, info = dynamics.step(
            state, action, params, self.config, self.mjx_model, self._ws_low, self._ws_high)
        return self.get_obs(new_state, params), new_state, r, terminated, truncated, info

    # ---- templates, hierarchies, rendering (other modules) ---------------------
    def templates(self) -> dict:
        from smjax.envs.fetch.templates import make_templates

        return make_templates(self.num_blocks)

    def hierarchies(self) -> dict:
        from smjax.envs.fetch.templates import make_hierarchies

        return make_hierarchies(self)

    def render(self, state: FetchState, params: FetchParams | None = None,
               width: int = 480, height: int = 360):
        from smjax.envs.fetch.render import render_state

        return render_state(self, state, width=width, height=height)


def make_fetch(
    default_blocks: int,
    *,
    num_blocks: int | None = None,
    substeps: int = PhysicsConfig.substeps,
    timestep: float = PhysicsConfig.timestep,
    solver_iterations: int = PhysicsConfig.solver_iterations,
    ls_iterations: int = PhysicsConfig.ls_iterations,
    obs_include_goals: bool = False,
    max_steps: int | None = None,
) -> tuple[FetchEnv, FetchParams]:
    """Build (env, params) for N = ``num_blocks`` (or ``default_blocks``) blocks."""
    n = check_num_blocks(default_blocks if num_blocks is None else
                         parse_int("num_blocks", num_blocks, MIN_BLOCKS, MAX_BLOCKS))
    # strict: a truncated 2.7 substeps or a NaN timestep would silently change the physics
    physics = PhysicsConfig(timestep=parse_float("timestep", timestep, 0.0, 0.1, low_open=True),
                            substeps=parse_int("substeps", substeps, 1, 1000),
                            solver_iterations=parse_int("solver_iterations", solver_iterations, 1, 1000),
                            ls_iterations=parse_int("ls_iterations", ls_iterations, 1, 1000))
    env = FetchEnv(FetchConfig(num_blocks=n, physics=physics,
                               obs_include_goals=parse_bool("obs_include_goals", obs_include_goals)))
    params = env.default_params
    if max_steps is not None:
        steps = parse_int("max_steps", max_steps, 1, INT32_MAX)
        params = params.replace(max_steps=np.asarray(steps, np.int32))
    return env, params


def _factory(default_blocks: int):
    def factory(*, num_blocks: int | None = None, substeps: int = PhysicsConfig.substeps,
                timestep: float = PhysicsConfig.timestep,
                solver_iterations: int = PhysicsConfig.solver_iterations,
                ls_iterations: int = PhysicsConfig.ls_iterations,
                obs_include_goals: bool = False, max_steps: int | None = None):
        return make_fetch(default_blocks, num_blocks=num_blocks, substeps=substeps,
                          timestep=timestep, solver_iterations=solver_iterations,
                          ls_iterations=ls_iterations, obs_include_goals=obs_include_goals,
                          max_steps=max_steps)

    return factory


def register_all() -> None:
    """Register ``fetch/stack1`` .. ``fetch/stack6``."""
    for n in range(MIN_BLOCKS, MAX_BLOCKS + 1):
        paper = " (paper)" if n in (3, 4) else ""
        register(f"fetch/stack{n}", _factory(n),
                 f"MJX gripper stacks {n} block(s) into a tower{paper}; num_blocks overrides N")
