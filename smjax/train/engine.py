"""The compiled core shared by every method: level chunks, the policy bank, evaluation.

One compiled ``chunk`` serves every level of every method: the option being trained,
the option each episode starts from and the set of learned options are traced
arrays, and every learner has the same padded action head (all primitives + all
templates, masked per option). Seeds are a leading ``vmap`` axis.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from smjax.agents.smdp import carry_pending
from smjax.core.env import select_tree
from smjax.options.hierarchy import Hierarchy
from smjax.options.runner import NO_OPTION, Controls, EnvCarry, HierarchyRunner, TickStats
from smjax.train.config import TrainConfig


class SeedState(NamedTuple):
    carry: EnvCarry
    learner: Any
    key: jax.Array


def frozen_mode(cfg: TrainConfig) -> str:
    if cfg.frozen_policy != "auto":
        return cfg.frozen_policy
    return "greedy" if cfg.algo == "dqn" else "sample"


class Engine:
    """Builds the jitted, seed-vmapped functions for one (env, hierarchy, agent, config)."""

    def __init__(self, env, env_params, hierarchy: Hierarchy, agent, cfg: TrainConfig):
        self.env, self.env_params, self.h, self.agent, self.cfg = env, env_params, hierarchy, agent, cfg
        mode = frozen_mode(cfg)
        self.runner = HierarchyRunner(env, env_params, hierarchy, agent, gamma=cfg.gamma,
                                      frozen_policy=mode, allow_teleport=True,
                                      reset_on_learner_end=not cfg.continue_episodes)
        # Evaluation: the final product alone, no teleports (leaf controllers still run).
        self.eval_runner = HierarchyRunner(env, env_params, hierarchy, agent, gamma=cfg.gamma,
                                           frozen_policy=mode, allow_teleport=False)
        # Acceptance gate: the level's own setting (teleports above, calls from resets), but
        # the learner acts as it will once frozen; a level ends only when this passes too.
        self.gate_runner = HierarchyRunner(env, env_params, hierarchy, agent, gamma=cfg.gamma,
                                           frozen_policy=mode, allow_teleport=True,
                                           learner_acts_frozen=True)
        obs, _ = env.reset_env(jax.random.PRNGKey(0), env_params)
        self.example_obs = obs
        self.num_actions = hierarchy.num_actions
        self.chunk = jax.jit(jax.vmap(self._chunk, in_axes=(0, 0, 0, 0, None, None)),
                             donate_argnums=(0,))
        self.evaluate = jax.jit(jax.vmap(self._evaluate, in_axes=(0, 0, 0, 0)))
        self.gate = jax.jit(jax.vmap(self._gate, in_axes=(0, 0, 0, 0, None, None, None, 0)))
        self._init_one = jax.jit(lambda k: agent.init(k, self.example_obs, self.num_actions))
        self.reset = jax.jit(jax.vmap(self._reset, in_axes=(0, None)))

    # ---- state -----------------------------------------------------------------
    def init_learner(self, keys: jax.Array):
        """Fresh learner states for each seed (leading axis S).

        Initialised one seed at a time and stacked (once per level, so cheap): without the
        scheduler flag set in ``smjax/__init__.py``, XLA:CPU (jaxlib 0.10) deadlocks running
        ``jit(vmap(init))`` of these networks for some sizes; this keeps init safe even when
        a user has opted out of that flag.
        """
        states = [self._init_one(k) for k in keys]
        return jax.tree.map(lambda *xs: jnp.stack(xs), *states)

    def _reset(self, key: jax.Array, start: jax.Array) -> EnvCarry:
        controls = Controls(jnp.asarray(NO_OPTION), start, jnp.zeros((self.h.num_options,), bool))
        return self.runner.reset(key, controls, self.cfg.num_envs)

    def new_bank(self, learner_states) -> Any:
        """Policy bank per seed: [S, num_options, ...] copies of the learners' initial params."""
        n = self.h.num_options
        return jax.tree.map(lambda p: jnp.repeat(p[:, None], n, axis=1), learner_states.params)

    @staticmethod
    def store_in_bank(bank, params, option: int):
        return jax.tree.map(lambda b, p: b.at[:, option].set(p), bank, params)

    # ---- one compiled chunk: updates_per_chunk x (rollout + update) ---------------
    def _chunk(self, state: SeedState, active, bank, learned, learner, start):
        controls = Controls(learner, start, learned)
        runner, agent, cfg = self.runner, self.agent, self.cfg

        def update_step(st: SeedState, _):
            key, k_roll, k_upd = jax.random.split(st.key, 3)

            def tick_fn(c, k):
                c, tr, ends = runner.tick(c, k, st.learner, bank, controls)
                return c, (tr, TickStats.of(ends))

            carry, (traj, stats) = jax.lax.scan(
                tick_fn, st.carry, jax.random.split(k_roll, cfg.rollout_ticks))
            # Decisions whose option still runs train in the next rollout, once complete.
            traj, pending = carry_pending(carry.pending, traj)
            carry = carry.replace(pending=pending)
            learner_state, metrics = agent.update(st.learner, traj, k_upd)
            stats = jax.tree.map(lambda x: x.sum(0), stats)
            return SeedState(carry, learner_state, key), (stats, metrics)

        new, (stats, metrics) = jax.lax.scan(update_step, state, None, cfg.updates_per_chunk)
        new = select_tree(active, new, state)
        stats = jax.tree.map(lambda x: jnp.where(active, x, jnp.zeros_like(x)), stats)
        return new, stats, metrics

    # ---- evaluation: one episode per environment, the first to finish -------------------
    def _first_episodes(self, runner: HierarchyRunner, key, learner_state, bank, controls,
                        num_envs: int, max_ticks: int, skip=False) -> dict:
        """Run ``num_envs`` environments until each has finished one learner episode (or
        ``max_ticks``); each environment's first episode counts, so short episodes are not
        over-represented, and one still unfinished at ``max_ticks`` counts as a failure.
        ``skip``: start as finished (under ``vmap`` a skipped seed does not keep the loop
        running for the others; its result is meaningless)."""
        k_reset, key = jax.random.split(key)
        carry = runner.reset(k_reset, controls, num_envs)

        def cond(c):
            _, _, done, _, _, t = c
            return jnp.logical_and(~done.all(), t < max_ticks)

        def body(c):
            carry, key, done, ret, success, t = c
            key, k = jax.random.split(key)
            carry, _, ends = runner.tick(carry, k, learner_state, bank, controls)
            first = ends.finished & ~done
            ret = jnp.where(first, ends.ret, ret)
            success = jnp.where(first, ends.success, success)
            return carry, key, done | ends.finished, ret, success, t + 1

        zeros = jnp.zeros((num_envs,), jnp.float32)
        init = (carry, key, jnp.full((num_envs,), skip, bool), zeros, zeros, jnp.asarray(0))
        _, _, done, ret, success, ticks = jax.lax.while_loop(cond, body, init)
        return {"return": ret.mean(), "success": success.mean(), "completed": done.mean(),
                "env_steps": ticks * num_envs}

    def _evaluate(self, key, bank, learned, learner_state):
        """The trained hierarchy alone (root on the stack, no teleports, nobody learning)."""
        controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0), learned)
        # learner_state never decides (no learner in evaluation); the tick needs one
        return self._first_episodes(self.eval_runner, key, learner_state, bank, controls,
                                    self.cfg.eval_envs, self.cfg.eval_max_ticks)

    def _gate(self, seed_key, state: SeedState, bank, learned, learner, start, attempt, due):
        """The learner's option as it will be frozen, called where the levels above call it
        (``attempt`` varies the episodes between attempts, deterministically; a seed not
        ``due`` is skipped)."""
        controls = Controls(learner, start, learned)
        key = jax.random.fold_in(seed_key, attempt)
        return self._first_episodes(self.gate_runner, key, state.learner, bank, controls,
                                    self.cfg.gate_envs, self.cfg.gate_max_ticks, skip=~due)
