"""How the tick runs the policy bank: every frozen option's scores, the learner's pick
when it acts as it will once frozen, and the frozen picks at their temperatures.

A mixin of :class:`~smjax.options.runner.HierarchyRunner`, kept apart so that the tick's
file holds the tick. It reads the runner's ``agent``, ``h`` (the hierarchy) and
``frozen_eval``; how the policies pick comes from the tick's ``Controls``
(``temperature``; ``frozen_temperature`` gives a run's).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.transition import ActOutput
from smjax.options.carry import Controls

# how the tick evaluates the policy bank: only the learned options that can decide (a loop
# over them), every option at once (one batched apply), or by the backend (auto)
FROZEN_EVALS = ("auto", "learned", "all")


def option_temperatures(root: float, templates: float, num_options: int) -> np.ndarray:
    """float32 [O]: the root's (option 0) temperature, then every template's."""
    return np.asarray([root] + [templates] * (num_options - 1), np.float32)


def frozen_temperature(policy: str, option_temperature: float,
                       num_options: int) -> float | np.ndarray:
    """``Controls.temperature`` of a run whose frozen policies act by ``policy``: 0.0
    (greedy: the argmax alone), or a sample with the root at 1 and every template at
    ``option_temperature`` (one Python float where the two agree, else float32 [O])."""
    if policy not in ("greedy", "sample"):
        raise ValueError(f"frozen_policy must be 'greedy' or 'sample', got {policy!r}")
    if not option_temperature > 0:
        raise ValueError(f"option_temperature must be > 0, got {option_temperature}")
    if policy == "greedy":
        return 0.0
    if float(option_temperature) == 1.0:
        return 1.0
    return option_temperatures(1.0, float(option_temperature), num_options)


class PolicyBank:
    """The runner's policy-bank methods (see the module docstring)."""

    def _act_frozen(self, learner_state, obs, mask, key, controls: Controls, *hidden):
        """The learner picks as the bank will run it once frozen (the level's gate); with no
        learner (evaluation: ``controls.learner`` NO_OPTION, or no ``learner_state`` at all)
        its network is not run. A recurrent learner passes its memory ``hidden`` and gets
        ``(act, memory after)`` back."""
        if learner_state is None:  # nobody learns: the learner's choice is never read
            out = (jnp.zeros(mask.shape, jnp.float32),) + hidden
        else:
            def own():
                out = self.agent.policy_logits(learner_state.params, obs, *hidden)
                return out if hidden else (out,)

            shape = jax.eval_shape(own)
            out = jax.lax.cond(controls.learner >= 0, own,
                               lambda: jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shape))
        action = self._frozen_pick(jnp.where(mask, out[0], -1e9), key, controls,
                                    controls.learner).astype(jnp.int32)
        zeros = jnp.zeros(action.shape, jnp.float32)
        act = ActOutput(action, zeros, zeros)
        return (act, out[1]) if hidden else act

    def frozen_logits(self, bank_params, obs: jax.Array, controls: Controls,
                      hidden: jax.Array | None = None):
        """[O, B, A] scores of the frozen policies that can decide now: the learned options
        other than the learner (the rest are never read and stay 0). A recurrent policy
        reads each option's memory ``hidden`` [B, O, H] and gives ``(scores, every
        option's memory after choosing [O, B, H])``.

        ``frozen_eval="learned"``: a loop over just those options, not a vmap over the
        whole bank: in top-down training most of the bank is not learned yet (level 1: none
        of it), and a policy's first layer on a wide observation is the tick's largest cost
        on a CPU. Under a ``vmap`` over seeds the loop runs as often as the seed with the
        most learned options needs. ``"all"``: one batched apply over the whole bank (on a
        GPU one wide kernel costs less than a loop of small ones); the unneeded rows are
        computed but never read.
        """
        memory = () if hidden is None else (jnp.swapaxes(hidden, 0, 1),)   # [O, B, H]
        if self.frozen_eval == "all":
            return jax.vmap(self.agent.policy_logits, (0, None) + (0,) * len(memory))(
                bank_params, obs, *memory)
        num_options = self.h.num_options
        need = controls.learned & (jnp.arange(num_options) != controls.learner)
        order = jnp.argsort(~need)  # the needed option ids first (argsort is stable)
        first = jax.tree.map(lambda p: p[0], bank_params)
        shape = jax.eval_shape(self.agent.policy_logits, first, obs,
                               *(m[0] for m in memory))
        out = jax.tree.map(lambda s: jnp.zeros((num_options,) + s.shape, s.dtype), shape)

        def one(i, out):
            option = order[i]
            params = jax.tree.map(lambda p: p[option], bank_params)
            new = self.agent.policy_logits(params, obs, *(m[option] for m in memory))
            return jax.tree.map(lambda o, n: o.at[option].set(n), out, new)

        return jax.lax.fori_loop(0, need.sum(), one, out)

    def _frozen_pick(self, logits: jax.Array, key: jax.Array, controls: Controls,
                     option: jax.Array | None = None) -> jax.Array:
        """A frozen policy's choice from masked scores (last axis): argmax at temperature 0,
        else a sample at the temperature. ``logits`` are every option's [O, B, A], or, with
        ``option``, that one option's [B, A] (a per-option temperature then picks its own)."""
        temperature = controls.temperature
        if isinstance(temperature, float):  # known when tracing: compute only that pick
            if temperature == 0.0:
                return jnp.argmax(logits, -1)
            return jax.random.categorical(key, logits / temperature, -1)
        temperature = jnp.asarray(temperature, jnp.float32)
        if temperature.ndim == 1:  # one per option
            temperature = (temperature[jnp.maximum(option, 0)] if option is not None
                           else temperature.reshape((-1,) + (1,) * (logits.ndim - 2)))
        sample = jax.random.categorical(
            key, logits / jnp.maximum(temperature, 1e-6)[..., None], -1)
        return jnp.where(temperature > 0, sample, jnp.argmax(logits, -1))
