"""Every learned option's own record of a tick, for joint fine-tuning.

In a fine-tuning *turn* one option learns while the others act frozen, so each option
trains on the decisions of roughly one episode in five. *Joint* fine-tuning lets every
learned option learn from every episode: each acts through its own learner's ``act``
(exploring as its learner does), and the tick records, per option, what that option's
learner would have recorded had it been the only learner:

* ``decision``: the option chose in this tick (``Decision.chose``) and is learned (a
  scripted policy's or controller's choices train nothing);
* ``reward``: the root's is the environment's reward; a template's is its F_o
  (``satisfied`` while it is on the stack), plus its side-cost shaping where on;
* ``done``: the option's run ended in this tick (it was on the stack before the pops and
  is not after them), or the episode did;
* ``action``, ``log_prob``, ``value``, ``action_mask``: its own (``value`` 0 until the
  update fills it in where the agent gives ``option_values``).

* ``discount``: the tick's discount at the option's own gamma, the one its level trained
  its values at (``TrainConfig.levels``: Fetch's recipe trains its root at 0.99 and its
  place options at 0.96). One gamma shared by every option re-fits some of them to a
  horizon they were not trained for: on Fetch, the place options at 0.99, where a tick
  of idling costs them 1% of their value.

The observation is shared by all options. A record is a ``Transition`` whose per-option
fields are ``[B, O]`` (``[B, O, A]`` for the mask); under a rollout's scan they become
``[T, B, O]``; ``OPTION_AXES`` names the option axis of each field (the observation is
shared, not copied per option). The trainer hands every option's record to the learners
at once (``smjax.agents.option_batch``).

Each option's rows are those of the option alone: its decisions, its reward, its ends;
nothing of another option's record reaches it (tests/test_joint.py checks the masks).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.core.transition import ActOutput, Transition

# a rollout's joint record [T, B, O]: which axis of each field is the option axis (None:
# shared by every option), for ``jax.vmap(update, in_axes=(0, ..., OPTION_AXES, ...))``
OPTION_AXES = Transition(obs=None, action=2, action_mask=2, log_prob=2, value=2, decision=2,
                         reward=2, discount=2, done=2, hidden=None)


def option_rewards(reward: jax.Array, satisfied: jax.Array, on: jax.Array,
                   shaping: jax.Array | float = 0.0) -> jax.Array:
    """float [B, O]: each option's reward for this tick: the environment's ``reward`` [B]
    for the root (option 0), a template's F_o (``satisfied`` [B, O] while ``on`` the stack
    before the pops) for the others, plus ``shaping`` [B, O] (a template's side cost,
    zero where the template is off the stack)."""
    template = (on & satisfied).astype(jnp.float32)
    root = jnp.arange(on.shape[-1]) == 0
    return jnp.where(root[None, :], reward.astype(jnp.float32)[:, None], template) + shaping


def option_ends(on_before: jax.Array, on_after: jax.Array, reset: jax.Array) -> jax.Array:
    """bool [B, O]: each option's run ended in this tick: it was on the stack before the
    pops and is not after them, or the environment starts a new episode (``reset`` [B])."""
    return (on_before & ~on_after) | reset[:, None]


def option_transitions(obs: jax.Array, acts: ActOutput, masks: jax.Array, chose: jax.Array,
                       learned: jax.Array, reward: jax.Array, discount: jax.Array,
                       done: jax.Array) -> Transition:
    """The tick's joint record: ``acts`` are every option's [O, B] (its own ``act``),
    ``masks`` [B, O, A], ``chose`` [B, O] (options that chose in this tick), ``learned``
    [O] (options that learn), ``reward`` and ``done`` [B, O] (``option_rewards``,
    ``option_ends``), ``discount`` [B, O] (each option's own gamma), ``obs`` [B, ...]
    shared."""
    return Transition(
        obs=obs, action=acts.action.T.astype(jnp.int32), action_mask=masks,
        log_prob=acts.log_prob.T, value=acts.value.T, decision=chose & learned[None, :],
        reward=reward, discount=discount, done=done)


def every_option_acts(agent, learners, obs: jax.Array, masks: jax.Array,
                      key: jax.Array) -> ActOutput:
    """Every option's exploring choice [O, B] from its own learner (``learners``: leading
    axis O; ``masks`` [B, O, A]), each with its own key. Where the agent gives
    ``option_values``, the values are left 0 (so its critics do not run here): the update
    fills them in on the decisions alone."""
    keys = jax.random.split(key, masks.shape[1])
    acts = jax.vmap(agent.act, (0, None, 1, 0))(learners, obs, masks, keys)
    if agent.option_values is not None:
        acts = acts._replace(value=jnp.zeros_like(acts.value))
    return acts
