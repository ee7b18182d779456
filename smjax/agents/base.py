"""The interface between learners and the (hierarchical) rollout machinery.

``Transition`` and ``ActOutput`` live in ``smjax.core.transition`` (below both the option
machinery and the learners) and are re-exported here.

What a tick is, and how an option's ticks add up to one SMDP decision, is told in
``smjax.core.transition``.

An ``Agent`` is a bundle of pure functions closed over the learner's config:

* ``init(key, example_obs, num_actions) -> state`` (state is a pytree with ``.params``)
* ``act(state, obs[B], mask[B, A], key) -> ActOutput`` (exploring behaviour policy)
* ``update(state, traj: Transition[T, B], key) -> (state, metrics)``: trains on the
  decisions that complete inside ``traj``; one still running at the end is the caller's
  to carry into the next rollout (``smjax.agents.smdp.carry_pending``)
* ``policy_logits(params, obs[B]) -> logits[B, A]`` (greedy scores for a frozen policy
  in the policy bank: actor logits for policy-gradient learners, Q-values for DQN)
* ``frozen_policy``: how a frozen copy acts by default, "sample" (from the logits, for a
  stochastic policy) or "greedy" (argmax, for value-based learners whose scores are not
  a distribution)
* ``warm_start(state, params) -> state``: a fresh state that continues from trained
  ``params`` (fine-tuning); exploration schedules start where they ended
* ``update_options(states, batch, key) -> (states, metrics)`` (optional): one update of
  a learner per option (``states``: leading axis O) on an ``OptionBatch``
  (``smjax.agents.option_batch``), each option from its own decisions only, with the
  same results as ``update`` option by option; its work follows the decisions in the
  batch. None: ``option_batch.each_option(update)`` runs ``update`` once per option
* ``option_values(states, obs[T, B], decision[T, B, O]) -> value[T, B, O]`` (optional):
  every option's ``ActOutput.value`` on its own decisions of a joint rollout (0 elsewhere),
  with work that follows the decisions. Where given, a joint rollout records no value and
  these fill them in before the update (a learner whose critic runs apart from its actor
  saves running every option's critic at every tick)
* ``hidden_size``: 0 for a memoryless policy. A *recurrent* learner (``hidden_size`` H > 0)
  carries a memory ``h [B, H]`` from each of its decisions to its next one:
  ``act(state, obs, mask, key, h) -> (ActOutput, h')`` and
  ``policy_logits(params, obs, h) -> (logits, h')``. The runner keeps one memory per
  option and environment, zero when the option is pushed, advanced only on the option's
  own decisions; ``update`` reads the memory that entered each tick in
  ``Transition.hidden`` (``smjax.agents.ppo`` trains through it by backpropagation
  through time)

A learner's state carries ``hp``: its config's fields declared ``traced``
(:mod:`smjax.agents.config`), as float32 scalars (:func:`hyper_params`), one per slot
under ``vmap``. The learner reads those values from its state rather than closing over
them, so they may differ between the slots of one compiled program (a hyper-parameter
sweep compiles once); the fields declared ``static`` fix shapes or the program's
structure and are closed over.
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from smjax.agents.config import traced_fields
from smjax.core.transition import ActOutput, Transition  # noqa: F401  (re-exported)


class Agent(NamedTuple):
    name: str
    init: Callable[..., Any]
    act: Callable[..., ActOutput]
    update: Callable[..., tuple[Any, dict]]
    policy_logits: Callable[[Any, jax.Array], jax.Array]
    frozen_policy: str = "sample"
    warm_start: Callable[[Any, Any], Any] = lambda state, params: state.replace(params=params)
    hidden_size: int = 0
    update_options: Callable[..., tuple[Any, dict]] | None = None
    option_values: Callable[..., jax.Array] | None = None


def hyper_params(config: Any) -> dict[str, jax.Array]:
    """The traced hyper-parameters a learner state carries (``state.hp``): the fields of
    ``config`` declared ``traced``, as float32 scalars."""
    return {name: jnp.asarray(getattr(config, name), jnp.float32)
            for name in traced_fields(config)}


def scale_by_lr(updates: Any, learning_rate: jax.Array) -> Any:
    """The last step of ``optax.adam`` with a traced learning rate (the same arithmetic
    as ``optax.scale_by_learning_rate``: updates times ``-learning_rate``)."""
    step = -learning_rate
    return jax.tree.map(lambda g: step * g, updates)
