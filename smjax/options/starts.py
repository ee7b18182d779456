"""How the tick's environments start episodes: the first reset, handing episodes to a new
learner, fresh starts (from a pool generated ahead, or one per reset) and the restart after
an episode ends.

A mixin of :class:`~smjax.options.runner.HierarchyRunner`, kept apart so that the tick's
file holds the tick. It reads the runner's ``env``, ``env_params``, ``h`` (the hierarchy),
``D`` (the stack depth), ``memory``, ``memory_size`` and ``reset_pool``.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.core.env import select_tree
from smjax.core.transition import no_pending
from smjax.options import phases
from smjax.options.carry import Controls, EnvCarry, ResetPool
from smjax.options.stack import stack_init


class EpisodeStarts:
    """The runner's episode-start methods (see the module docstring)."""

    def reset(self, key: jax.Array, controls: Controls, num_envs: int) -> EnvCarry:
        # split only for a pool: without one the starts are drawn from ``key`` itself
        k_envs, k_pool = jax.random.split(key) if self.reset_pool else (key, None)
        obs, state = self._fresh_starts(k_envs, num_envs)
        stack = jax.vmap(lambda _: stack_init(self.D, controls.start))(jnp.arange(num_envs))
        zeros_b = jnp.zeros((num_envs,), bool)
        pool = self._new_pool(k_pool) if self.reset_pool else None
        zeros_f = jnp.zeros((num_envs,), jnp.float32)
        hidden = (jnp.zeros((num_envs, self.h.num_options, self.memory_size), jnp.float32)
                  if self.memory_size else None)
        return EnvCarry(state, obs, stack, zeros_b, zeros_f, zeros_f,
                        no_pending(obs, self.h.num_actions, self.memory_size), pool, hidden)

    def hand_over(self, carry: EnvCarry) -> EnvCarry:
        """The same environments, episodes and stacks for a new learner: what belonged to
        the old one (its pending decision, whether it acted in this episode, its return) is
        cleared, so the new learner's record starts at its own first decision."""
        B = carry.obs.shape[0]
        zeros_f = jnp.zeros((B,), jnp.float32)
        return carry.replace(
            learner_started=jnp.zeros((B,), bool), learner_return=zeros_f,
            pending=no_pending(carry.obs, self.h.num_actions, self.memory_size))

    def _fresh_starts(self, key: jax.Array, n: int):
        obs, state = jax.vmap(self.env.reset_env, (0, None))(jax.random.split(key, n),
                                                             self.env_params)
        # An environment's weakly typed leaf (``t=jnp.asarray(0)``) comes back strongly
        # typed from a checkpoint or a copy through the host: made strong here, the run's
        # state has one type wherever it comes from, so a resumed run or a CPU's seed
        # groups call the programs compiled for it.
        state = jax.tree.map(lambda x: x.astype(x.dtype) if getattr(x, "weak_type", False) else x,
                             state)
        return self.policy_obs(obs), state

    def policy_obs(self, raw_obs: jax.Array) -> jax.Array:
        """What the policies see of fresh episodes' observations (leading axis B)."""
        return raw_obs if self.memory is None else self.memory.start(raw_obs)

    def _new_pool(self, key: jax.Array) -> ResetPool:
        obs, state = self._fresh_starts(key, self.reset_pool)
        return ResetPool(obs, state, jnp.zeros((), jnp.int32))

    def refill(self, carry: EnvCarry, key: jax.Array) -> EnvCarry:
        """New episode starts in the pool (no-op without one)."""
        if carry.pool is None:
            return carry
        return carry.replace(pool=self._new_pool(key))

    def _next_starts(self, carry: EnvCarry, reset: jax.Array, key: jax.Array):
        """(obs, state) of a new episode for every environment (used where ``reset``), and
        the pool after handing them out."""
        if carry.pool is None:
            obs, state = self._fresh_starts(key, reset.shape[0])
            return obs, state, None
        pool = carry.pool
        slot = (pool.next + jnp.cumsum(reset) - 1) % self.reset_pool
        take = lambda x: x[slot]  # noqa: E731
        obs, state = take(pool.obs), jax.tree.map(take, pool.state)
        return obs, state, pool.replace(next=(pool.next + reset.sum()) % self.reset_pool)

    def _restart(self, carry: EnvCarry, acc: phases.Accounts, stack, obs, state,
                 controls: Controls, key: jax.Array) -> EnvCarry:
        """The next tick's carry: where an episode ended, a new start with a fresh stack."""
        B = carry.obs.shape[0]
        obs_re, state_re, pool = self._next_starts(carry, acc.reset, key)
        fresh = jax.vmap(lambda _: stack_init(self.D, controls.start))(jnp.arange(B))
        return EnvCarry(
            env_state=jax.vmap(select_tree)(acc.reset, state_re, state),
            obs=jax.vmap(select_tree)(acc.reset, obs_re, obs),
            stack=jax.vmap(select_tree)(acc.reset, fresh, stack),
            learner_started=acc.started, learner_return=acc.learner_return,
            task_return=acc.task_return,
            pending=carry.pending,  # the engine updates it once per rollout (carry_pending)
            pool=pool,
            hidden=carry.hidden,  # the tick's memory update follows (``_next_memory``)
        )
