"""The hierarchical tick: one primitive environment step for every environment.

In each tick, for each environment, options on the execution stack decide from the top
down until a primitive action is fixed: the learner (the option being trained) samples
from its own policy, learned options use their frozen policy from the *policy bank*, an
option with a scripted policy (``Hierarchy.policies``) that is neither learned nor the
learner decides by its script, an unlearned template on the stack plays its scripted
controller, and calling an unlearned template that has a teleport jumps the state (the
jump and its primitive action are that tick's single environment step). After the step, every stack entry
whose template is satisfied or out of ticks is popped (with everything above it).

Only the learner's own choices become training transitions (``decision``); its reward
is the environment's reward when it is the root option, else ``satisfied`` of its
template (F_o); the per-tick discount is gamma, or gamma**d for a teleported call; the
learner's episode (``done``) ends with the environment's or when its option ends.
The tick is a string of pure phases (``smjax.options.phases``: decide, realise, step,
pop, account); what the templates say about states (satisfied, failed, side costs, the
task's success) comes from ``smjax.options.template_fields``. The machinery is generic:
it sees the environment only through ``reset_env``, ``step_env`` and the templates of a
:class:`~smjax.options.Hierarchy`.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.transition import ActOutput, Transition
from smjax.options import joint, phases, template_fields
from smjax.options.bank import (  # noqa: F401 - re-exported
    FROZEN_EVALS, PolicyBank, option_temperatures,
)
from smjax.options.carry import (  # noqa: F401 - re-exported: the runner's public types
    NO_OPTION, Controls, EnvCarry, EpisodeEnds, ResetPool, TickStats,
)
from smjax.options.hierarchy import Hierarchy, check_success
from smjax.options.memory import make_memory
from smjax.options.realise import families, primitive_action, run_family
from smjax.options.stack import options_on
from smjax.options.starts import EpisodeStarts

_NEVER = np.iinfo(np.int32).max // 2


class TickPlan(NamedTuple):
    """What a tick decided before the environment steps (leading axis B)."""

    act: ActOutput              # the learner's pick
    learner_mask: jax.Array     # its action mask [B, A]
    memory: jax.Array | None    # every option's memory after choosing now [B, O, H]
    decision: phases.Decision
    state_in: Any               # the state to step from (a teleport's jump applied)
    action: jax.Array           # the primitive action [B, ...]
    teleported: jax.Array       # the option whose teleport jumped (NO_OPTION: none)


class HierarchyRunner(PolicyBank, EpisodeStarts):
    """Compiles a hierarchy over an environment into batched tick/reset functions.

    What it is built from fixes the program's structure (the environment, hierarchy and
    agent; ``reset_pool``: episode starts generated ahead, 0 for none; ``frozen_eval``: how
    the policy bank is evaluated; ``policy_memory``: what the policies see); every setting
    of a tick (discount, teleports, episodes, temperatures, acting frozen) comes with the
    tick's ``Controls``.
    """

    def __init__(self, env, env_params, hierarchy: Hierarchy, agent, *, reset_pool: int = 0,
                 frozen_eval: str = "auto", policy_memory: str = "none"):
        self.env, self.env_params, self.h, self.agent = env, env_params, hierarchy, agent
        check_success(hierarchy, env, env_params)
        if isinstance(reset_pool, bool) or not isinstance(reset_pool, int) or reset_pool < 0:
            raise ValueError(f"reset_pool must be an integer >= 0, got {reset_pool!r}")
        self.reset_pool = reset_pool
        if frozen_eval not in FROZEN_EVALS:
            raise ValueError(f"frozen_eval must be one of {FROZEN_EVALS}, got {frozen_eval!r}")
        if frozen_eval == "auto":  # a loop of small applies is cheaper on a CPU, one wide one on a GPU
            frozen_eval = "learned" if jax.default_backend() == "cpu" else "all"
        self.frozen_eval = frozen_eval
        tpls = hierarchy.template_list
        self.templates = tpls
        self.P = hierarchy.num_primitives
        self.D = hierarchy.stack_depth
        self.child_mask = jnp.asarray(hierarchy.child_mask())
        self.k_max = jnp.asarray([_NEVER] + [t.k_max for t in tpls], jnp.int32)
        self.nominal = jnp.asarray([1] + [t.nominal_steps for t in tpls], jnp.float32)
        self.has_teleport = np.array([False] + [t.teleport is not None for t in tpls])
        self.has_controller = np.array([False] + [t.controller is not None for t in tpls])
        space = env.action_space(env_params)
        # what the policies see: the observation, or it with a one-step memory (memory.py;
        # the observation's shape is traced only for a memory, not on every run's start-up)
        self.memory = make_memory(policy_memory, space, lambda: jax.eval_shape(
            lambda k: env.reset_env(k, env_params)[0], jax.random.PRNGKey(0)))
        self.action_shape = tuple(space.shape)
        self.action_dtype = space.dtype
        self.teleport_families = families([t.teleport for t in tpls])
        self.controller_families = families([t.controller for t in tpls])
        # scripted policies: (option id, policy, its children's action ids)
        self.policies = [(hierarchy.option_index(name), hierarchy.policies[name],
                          np.asarray([hierarchy.action_index(c) for c in hierarchy.children[name]],
                                     np.int32))
                         for name in hierarchy.scripted]
        self.has_policy = np.array([n in hierarchy.policies for n in hierarchy.option_names])
        # a recurrent learner's memory width (0: memoryless policies, no memory carried)
        self.memory_size = 0 if agent is None else int(agent.hidden_size)

    def _initiation(self, state) -> jax.Array:
        """bool [O]: which options may start in ``state`` (one environment)."""
        return template_fields.per_option(self.templates, self.env_params, state,
                                          "initiation", True, bool)

    @staticmethod
    def teleports_on(controls: Controls) -> jax.Array:
        """bool: unlearned templates with a teleport jump (else they are not callable)."""
        return jnp.asarray(controls.teleport)

    def deciding(self, learned: jax.Array, teleport_on: jax.Array | bool) -> jax.Array:
        """bool [num_options]: options that choose when on the stack (besides the learner):
        the learned ones, and those with a scripted policy (``phases.deciding_options``)."""
        if not self.policies:  # no scripted policy: the learned options alone, no extra ops
            return learned
        return phases.deciding_options(learned, jnp.asarray(self.has_policy),
                                       jnp.asarray(self.has_teleport), teleport_on)

    def callable_options(self, learned: jax.Array, learner: jax.Array,
                         teleport: jax.Array | bool) -> jax.Array:
        """bool [num_options]: options that can run now (learned, the learner, or realisable;
        ``teleport``: whether a teleport realises an unlearned template now)."""
        ids = jnp.arange(self.h.num_options)
        realise = jnp.asarray(self.has_controller) | (jnp.asarray(self.has_teleport) & teleport)
        return learned | realise | (ids == learner)

    def action_masks(self, init_ok: jax.Array, callable_: jax.Array) -> jax.Array:
        """bool [num_options, A]: what each option may choose in this state."""
        call_ok = (init_ok & callable_)[1:]
        allowed = jnp.concatenate([jnp.ones((self.P,), bool), call_ok])
        return self.child_mask & allowed[None, :]

    # ---- one tick for the whole batch: decide, realise, step, pop, account -------------
    def primitive_actions(self, carry: EnvCarry, key: jax.Array, learner_state, bank_params,
                          controls: Controls) -> jax.Array:
        """The primitive action [B, ...] that ``tick`` with the same arguments steps with
        (where a teleport jumps, the jump's own action)."""
        keys = tuple(jax.random.split(key, 6)[:4])  # tick's split: the same picks
        return self._plan(carry, keys, learner_state, bank_params, controls).action

    def _plan(self, carry: EnvCarry, keys: tuple, learner_state, bank_params,
              controls: Controls) -> "TickPlan":
        """The decide and realise phases of a tick, before the environment steps."""
        k_act, k_frozen, k_ctrl, k_tp = keys
        teleport_on = self.teleports_on(controls)
        deciding = self.deciding(controls.learned, teleport_on)
        callable_ = self.callable_options(deciding, controls.learner, teleport_on)
        act, learner_mask, frozen, memory = self.policy_choices(
            carry, learner_state, bank_params, controls, callable_, k_act, k_frozen)
        pushable = phases.pushable_options(
            deciding, controls.learner, jnp.asarray(self.has_controller),
            jnp.asarray(self.has_teleport), teleport_on)
        # (joint: nobody is "the learner"; every option's pick is in ``frozen``)
        own = frozen[:, 0] if controls.joint else act.action
        decision = jax.vmap(lambda s, f, l: phases.decide(
            s, f, l, learner=controls.learner, learned=deciding, pushable=pushable,
            callable_=callable_, num_primitives=self.P))(carry.stack, frozen, own)
        state_in, action, teleported = self._realise(decision, carry.env_state, controls,
                                                      k_ctrl, k_tp)
        return TickPlan(act, learner_mask, memory, decision, state_in, action, teleported)

    def tick(self, carry: EnvCarry, key: jax.Array, learner_state, bank_params,
             controls: Controls) -> tuple[EnvCarry, Transition, EpisodeEnds]:
        """One primitive step for every environment (leading axis B).

        ``learner_state`` is what the agent's ``act`` takes; where the learner acts frozen
        (``Controls.acts_frozen``) only its ``params`` are read, and it may be None where
        nobody learns (``controls.learner`` is NO_OPTION: evaluation needs no learner). A
        runner built without an agent (``agent=None``: every decision scripted) takes None for
        ``learner_state`` and ``bank_params``, nobody learns and nothing is learned.
        """
        k_act, k_frozen, k_ctrl, k_tp, k_step, k_reset = jax.random.split(key, 6)
        act, learner_mask, memory, decision, state_in, action, teleported = self._plan(
            carry, (k_act, k_frozen, k_ctrl, k_tp), learner_state, bank_params, controls)
        obs, state, reward, terminated, truncated, info = phases.step(
            self.env, self.env_params, k_step, state_in, action)
        if self.memory is not None:
            obs = self.memory.after(carry.obs, obs, action)
        sat, stop = template_fields.stop_conditions(self.templates, self.env_params, state)
        popped = phases.pop(decision.stack, stop, self.k_max, controls.learner)

        discount = phases.tick_discount(teleported, self.nominal, controls.gamma)
        learner_idx = jnp.maximum(controls.learner, 0)
        on = options_on(decision.stack, self.h.num_options)  # before the pops
        shaping = template_fields.side_costs(self.templates, self.env_params, carry.env_state,
                                             state, on, controls.side_cost)
        acc = phases.account(
            started=carry.learner_started, learner_return=carry.learner_return,
            task_return=carry.task_return, decided=decision.learner_decided, reward=reward,
            env_done=terminated | truncated, popped=popped,
            learner_satisfied=sat[:, learner_idx],
            shaping=shaping if isinstance(shaping, float) else shaping[:, learner_idx],
            info_success=template_fields.task_success(self.h.success, self.env_params, state,
                                                      info),
            learner=controls.learner, start=controls.start,
            reset_on_learner_end=controls.resets_on_learner_end())
        if controls.joint:  # every option's own record (joint.py)
            transition = joint.option_transitions(
                carry.obs, act, learner_mask, decision.chose, controls.learned,
                joint.option_rewards(reward, sat, on, shaping), discount,
                joint.option_ends(on, options_on(popped.stack, self.h.num_options),
                                  acc.reset))
        else:
            transition = Transition(
                obs=carry.obs, action=act.action, action_mask=learner_mask,
                log_prob=act.log_prob, value=act.value, decision=decision.learner_decided,
                reward=acc.reward, discount=discount, done=acc.learner_done,
                hidden=None if memory is None else carry.hidden[:, learner_idx],
            )
        carry = self._restart(carry, acc, popped.stack, obs, state, controls, k_reset)
        if memory is not None:
            carry = carry.replace(hidden=self._next_memory(carry, decision.chose, memory,
                                                           acc.reset))
        return carry, transition, acc.ends

    def _next_memory(self, carry: EnvCarry, chose: jax.Array, memory: jax.Array,
                     reset: jax.Array) -> jax.Array:
        """[B, O, H]: each option's memory after this tick: advanced where the option chose
        (``memory``: every option's memory after choosing now), zero where it is no longer
        on the stack or its episode was reset, so each run of an option starts from zero."""
        hidden = jnp.where(chose[..., None], memory, carry.hidden)
        on = options_on(carry.stack, self.h.num_options)
        return jnp.where((on & ~reset[:, None])[..., None], hidden, 0.0)

    def policy_choices(self, carry: EnvCarry, learner_state, bank_params, controls: Controls,
                 callable_: jax.Array, k_act: jax.Array, k_frozen: jax.Array):
        """What each policy would pick now: the learner's act [B] (and its action mask
        [B, A]), and every frozen policy's masked pick [B, O] (read only where that option
        is on the stack and decides), a scripted policy's where its option is not learned;
        with a recurrent policy also every option's memory after choosing now [B, O, H]
        (the learner's from its own network; else None)."""
        init_ok = jax.vmap(self._initiation)(carry.env_state)                     # [B, O]
        masks = jax.vmap(lambda i: self.action_masks(i, callable_))(init_ok)      # [B, O, A]
        learner_mask = masks[:, jnp.maximum(controls.learner, 0)]                 # [B, A]
        B = carry.obs.shape[0]
        memory = None
        if controls.joint:  # every option explores through its own learner
            act = joint.every_option_acts(self.agent, learner_state, carry.obs, masks, k_act)
            frozen = self._scripted(act.action.T.astype(jnp.int32), carry, masks, controls,
                                    k_frozen)
            return act, masks, frozen, None
        if self.agent is None:  # every decision scripted: no network runs
            zeros = jnp.zeros((B,), jnp.float32)
            act = ActOutput(jnp.zeros((B,), jnp.int32), zeros, zeros)
            frozen = jnp.zeros((B, self.h.num_options), jnp.int32)
        else:
            learner = jnp.maximum(controls.learner, 0)
            own = () if carry.hidden is None else (carry.hidden[:, learner],)
            if controls.acts_frozen:
                act = self._act_frozen(learner_state, carry.obs, learner_mask, k_act, controls,
                                       *own)
            else:
                act = self.agent.act(learner_state, carry.obs, learner_mask, k_act, *own)
            logits = self.frozen_logits(bank_params, carry.obs, controls, carry.hidden)
            if carry.hidden is not None:
                (act, own_next), (logits, memory) = act, logits
                memory = jnp.swapaxes(memory, 0, 1)                                # [B, O, H]
                memory = memory.at[:, learner].set(
                    jnp.where(controls.learner >= 0, own_next, memory[:, learner]))
            # logits [O, B, A]
            logits = jnp.where(jnp.swapaxes(masks, 0, 1), logits, -1e9)
            frozen = self._frozen_pick(logits, k_frozen, controls)
            frozen = jnp.swapaxes(frozen, 0, 1).astype(jnp.int32)
        return act, learner_mask, self._scripted(frozen, carry, masks, controls, k_frozen), memory

    def _scripted(self, frozen: jax.Array, carry: EnvCarry, masks: jax.Array,
                  controls: Controls, k_frozen: jax.Array) -> jax.Array:
        """``frozen`` [B, O] with each scripted policy's pick where its option is not learned."""
        if not self.policies:
            return frozen
        # a key stream of its own: the other picks draw the same keys with or without
        # scripted policies
        keys = jax.random.split(jax.random.fold_in(k_frozen, 0x5C41), frozen.shape[0])
        picks = jax.vmap(self._scripted_picks)(keys, carry.env_state, masks)  # [B, n]
        for j, (option, _, _) in enumerate(self.policies):
            frozen = frozen.at[:, option].set(
                jnp.where(controls.learned[option], frozen[:, option], picks[:, j]))
        return frozen

    def _scripted_picks(self, key: jax.Array, state, masks: jax.Array) -> jax.Array:
        """int32 [len(policies)]: each scripted policy's pick as an action id (one
        environment; ``masks`` [O, A]). A policy gets its children's mask and returns a
        child index, clipped into range; a pick the mask forbids becomes the first allowed
        child, so a script can never call what a learned policy could not (an option
        that is not initiable, or not realisable now)."""
        out = []
        for option, policy, ids in self.policies:
            mask = masks[option][ids]
            child = jnp.asarray(policy(jax.random.fold_in(key, option), state, self.env_params,
                                       mask)).reshape(())
            child = jnp.clip(child, 0, len(ids) - 1)
            child = jnp.where(mask[child], child, jnp.argmax(mask))
            out.append(jnp.asarray(ids)[child])
        return jnp.stack(out).astype(jnp.int32)

    def _realise(self, decision: phases.Decision, env_state, controls: Controls,
                 k_ctrl: jax.Array, k_tp: jax.Array):
        """(state to step from, action [B, ...], teleported [B]): the primitive, overwritten
        by a scripted controller's action, or by a teleport's jump and action (teleports
        only where this tick allows them; a Python ``teleport=False`` compiles none)."""
        action = primitive_action(decision.primitive, self.action_shape, self.action_dtype)
        if self.controller_families:
            action = self.run_family(self.controller_families, k_ctrl, env_state,
                                      decision.scripted, action, controls=True)
        teleported = decision.teleported
        if controls.teleports() and self.teleport_families:
            teleported = jnp.where(self.teleports_on(controls), teleported, NO_OPTION)
            env_state, action = self.run_family(self.teleport_families, k_tp, env_state,
                                                 teleported, action, controls=False)
        return env_state, action, teleported

    def run_family(self, fams, key, state, chosen, action, *, controls: bool):
        """``realise.run_family`` with this runner's environment parameters."""
        return run_family(fams, key, state, chosen, action, self.env_params, self.action_dtype,
                          controls=controls)
