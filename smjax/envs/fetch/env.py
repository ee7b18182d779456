"""FetchEnv: stack N blocks into a tower with a floating MJX gripper.

Action: float32[4] in [-1, 1] (clipped). ``a[:3]`` moves the mocap target of the grip
point by ``action_scale`` (0.05 m) per step per unit, clamped to the workspace box; the
target moves along a straight line over the substeps, so the gripper is dragged smoothly
instead of jumping 5 cm in one physics step. ``a[3]`` moves both finger position targets
by 0.05 m per unit (+1 opens fully, -1 closes fully in one step, 0 keeps the current
target, so doing nothing keeps a grasp; the reference instead re-targets the current
finger position, which loosens the grip when the action is 0).

Episodes: truncated after ``params.max_steps`` (50 N) steps; never terminated (the
reference has no terminal state: a stacked tower must also be kept stacked).
``info``: ``score`` = (min(0, r) + N) / N, ``is_success`` = every block within 0.04 m of
its goal, ``placed`` = bool[N].
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from smjax.core import spaces
from smjax.core.env import Environment
from smjax.envs.fetch import model as fm
from smjax.envs.fetch import state as st
from smjax.envs.fetch.observation import blocks_placed, observation, reward, score
from smjax.envs.fetch.sampling import sample_blocks, sample_goals
from smjax.envs.fetch.state import FetchConfig, FetchParams, FetchState


class FetchEnv(Environment[FetchState, FetchParams]):
    """Fetch & Stack (see module docstring)."""

    success_in_unit_interval = True  # info["success"] is the score (min(0, r) + N) / N

    def __init__(self, config: FetchConfig = FetchConfig()):
        self.config = config
        self.num_blocks = config.num_blocks
        self.mj_model = fm.build_model(config.num_blocks, config.physics)
        self.index = fm.model_index(self.mj_model, config.num_blocks)
        self._check_layout()
        self.mjx_model = mjx.put_model(self.mj_model, impl="jax")
        self._data0 = mjx.make_data(self.mjx_model, impl="jax")
        lo = np.array(fm.GRIPPER_START, np.float32)
        self._ws_low = jnp.asarray(
            [lo[0] - fm.WORKSPACE_XY, lo[1] - fm.WORKSPACE_XY, fm.WORKSPACE_Z[0]], jnp.float32)
        self._ws_high = jnp.asarray(
            [lo[0] + fm.WORKSPACE_XY, lo[1] + fm.WORKSPACE_XY, fm.WORKSPACE_Z[1]], jnp.float32)

    def _check_layout(self) -> None:
        # state.py's accessors hard-code the qpos layout; fail loudly if the model drifts.
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
        return FetchParams(max_steps=jnp.asarray(50 * self.num_blocks, jnp.int32))

    def action_space(self, params: FetchParams | None = None) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (4,), jnp.float32)

    def observation_space(self, params: FetchParams | None = None) -> spaces.Box:
        return spaces.Box(-jnp.inf, jnp.inf, (self.config.obs_size,), jnp.float32)

    def get_obs(self, state: FetchState, params: FetchParams | None = None) -> jax.Array:
        return observation(state, self.config)

    def reset_env(self, key: jax.Array, params: FetchParams) -> tuple[jax.Array, FetchState]:
        key_goal, key_blocks = jax.random.split(key)
        goals = sample_goals(key_goal, params, self.num_blocks)
        blocks_xy = sample_blocks(key_blocks, goals[0, :2], params, self.config)
        start = jnp.asarray(fm.GRIPPER_START, jnp.float32)
        n = self.num_blocks
        block_qpos = jnp.concatenate(
            [blocks_xy, jnp.full((n, 1), fm.BLOCK_REST_Z, jnp.float32),
             jnp.tile(jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32), (n, 1))], axis=-1)
        open_fingers = jnp.full((2,), fm.FINGER_RANGE[1], jnp.float32)
        qpos = jnp.concatenate([
            start, jnp.asarray([1.0, 0.0, 0.0, 0.0], jnp.float32), open_fingers,
            block_qpos.ravel()])
        data = self._data0.replace(
            qpos=qpos,
            qvel=jnp.zeros_like(self._data0.qvel),
            ctrl=open_fingers,
            mocap_pos=start[None, :],
            mocap_quat=jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32),
        )
        data = mjx.forward(self.mjx_model, data)
        state = FetchState(data=data, goals=goals, step=jnp.zeros((), jnp.int32),
                           placed=jnp.zeros((n,), bool))
        state = state.replace(placed=blocks_placed(state, params))
        return observation(state, self.config), state

    def step_env(self, key: jax.Array, state: FetchState, action: jax.Array,
                 params: FetchParams):
        action = jnp.clip(jnp.asarray(action, jnp.float32).reshape(4), -1.0, 1.0)
        data = state.data
        old_target = data.mocap_pos[0]
        new_target = jnp.clip(old_target + params.action_scale * action[:3],
                              self._ws_low, self._ws_high)
        ctrl = jnp.clip(data.ctrl + fm.FINGER_RANGE[1] * action[3],
                        fm.FINGER_RANGE[0], fm.FINGER_RANGE[1])
        data = data.replace(ctrl=ctrl)
        substeps = self.config.physics.substeps

        def substep(d, frac):
            target = old_target + frac * (new_target - old_target)
            d = d.replace(mocap_pos=target[None, :])
            return mjx.step(self.mjx_model, d), None

        fracs = jnp.arange(1, substeps + 1, dtype=jnp.float32) / substeps
        data, _ = jax.lax.scan(substep, data, fracs)
        new_state = FetchState(data=data, goals=state.goals, step=state.step + 1,
                               placed=state.placed)
        placed = blocks_placed(new_state, params)
        new_state = new_state.replace(placed=placed)
        r = reward(new_state, params)
        # MJX has no divergence check of its own: a block squeezed between the fingers can
        # blow up to inf/NaN, which would poison every learner fed this observation. Such
        # an episode terminates (the auto-reset replaces it) with a finite observation and
        # no reward and no score (a zero reward would read as "all placed"), and says so in
        # info["physics_diverged"].
        diverged = ~(jnp.isfinite(data.qpos).all() & jnp.isfinite(data.qvel).all()
                     & (jnp.abs(data.qvel).max() < 1e3))
        episode_score = jnp.where(diverged, 0.0, score(r, self.num_blocks))
        r = jnp.where(diverged, 0.0, r)
        truncated = new_state.step >= params.max_steps
        info = {
            "score": episode_score,
            # the trainers' per-episode success of the root option: the paper's score
            "success": episode_score,
            "is_success": jnp.all(placed),
            "placed": placed,
            "physics_diverged": diverged,
        }
        obs = jnp.nan_to_num(observation(new_state, self.config), posinf=0.0, neginf=0.0)
        return obs, new_state, r, diverged, truncated, info

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
