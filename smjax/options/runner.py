"""The hierarchical tick: one primitive environment step for every environment.

In each tick, for each environment, options on the execution stack decide from the top
down until a primitive action is fixed: the learner (the option being trained) samples
from its own policy, learned options use their frozen policy from the *policy bank*, an
unlearned template on the stack plays its scripted controller, and calling an
unlearned template that has a teleport jumps the state (the jump and its primitive
action are that tick's single environment step). After the step, every stack entry
whose template is satisfied or out of ticks is popped (with everything above it).

Only the learner's own choices become training transitions (``decision``); its reward
is the environment's reward when it is the root option, else ``satisfied`` of its
template (F_o); the per-tick discount is gamma, or gamma**d for a teleported call; the
learner's episode (``done``) ends with the environment's or when its option ends.
The machinery is generic: it sees the environment only through ``reset_env``,
``step_env`` and the templates of a :class:`~smjax.options.Hierarchy`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from smjax.core.env import select_tree
from smjax.core.transition import ActOutput, Transition, no_pending
from smjax.options.hierarchy import Hierarchy, check_success
from smjax.options.template import Parametric
from smjax.options.stack import (
    ExecutionStack, stack_contains, stack_init, stack_push, stack_tick, stack_top, stack_truncate,
)

NO_OPTION = -1
# how the tick evaluates the policy bank: only the learned options that can decide (a loop
# over them), every option at once (one batched apply), or by the backend (auto)
FROZEN_EVALS = ("auto", "learned", "all")
_NEVER = np.iinfo(np.int32).max // 2


@struct.dataclass
class EnvCarry:
    """Per-environment rollout state (leading axis B)."""

    env_state: Any
    obs: jax.Array
    stack: ExecutionStack
    learner_started: jax.Array  # bool: the learner has acted in this episode
    learner_return: jax.Array   # float: learner reward collected in this episode
    task_return: jax.Array      # float: environment reward collected in this episode
    pending: Transition         # the learner's decision still running at the last rollout end
    pool: "ResetPool | None" = None  # pre-generated episode starts (None: reset in every tick)


@struct.dataclass
class ResetPool:
    """Episode starts generated ahead of time (leading axis P), handed out in order.

    Generating a fresh episode start for every environment in every tick (and throwing
    it away wherever the episode goes on) costs as much as the step itself in worlds
    with procedural generation; instead ``refill`` generates P starts once (the engine
    does it before every rollout) and each reset takes the next unused one, so within
    a rollout every episode gets its own fresh start unless more than P episodes end
    (then starts are reused, oldest first).
    """

    obs: jax.Array
    state: Any
    next: jax.Array  # int32: index of the next start to hand out (mod P)


@struct.dataclass
class EpisodeEnds:
    """Per-environment episode bookkeeping of one tick (leading axis B)."""

    reset: jax.Array     # bool: the environment was reset after this tick (every reset counts)
    finished: jax.Array  # bool: an episode in which the learner acted ended
    ret: jax.Array       # float: that episode's learner return (0 where not finished)
    success: jax.Array   # float: that episode's success (0 where not finished)
    decided: jax.Array   # bool: the learner decided in this tick
    task_end: jax.Array  # bool: a whole-task episode (root at the bottom) ended naturally
    task_success: jax.Array  # float: that episode's task success (0 where not ended)


@struct.dataclass
class TickStats:
    """Sums over the batch (and over ticks once reduced)."""

    env_episodes: jax.Array
    learner_episodes: jax.Array
    learner_return: jax.Array
    learner_success: jax.Array
    learner_decisions: jax.Array
    task_episodes: jax.Array
    task_success: jax.Array

    @staticmethod
    def of(ends: EpisodeEnds) -> "TickStats":
        return TickStats(
            env_episodes=ends.reset.sum(-1).astype(jnp.int32),
            learner_episodes=ends.finished.sum(-1).astype(jnp.int32),
            learner_return=ends.ret.sum(-1),
            learner_success=ends.success.sum(-1),
            learner_decisions=ends.decided.sum(-1).astype(jnp.int32),
            task_episodes=ends.task_end.sum(-1).astype(jnp.int32),
            task_success=ends.task_success.sum(-1),
        )


@dataclass(frozen=True)
class Controls:
    """Traced per-run controls of the tick (all arrays, so one compile serves every level).

    learner: option id being trained (NO_OPTION: evaluation, nobody learns).
    start: option placed at the bottom of the stack at each reset (0 = root; a template
      id starts that template directly from reset states, as bottom-up training does).
    learned: bool [num_options], options whose frozen policy is in the bank.
    teleport: bool, unlearned templates may be teleported (None: as the runner was built;
      False turns a teleporting runner into an evaluating one without another compile).
    continue_episodes: bool, the environment goes on when the learner's option ends (None:
      as the runner was built); its next episode starts where the levels above call it again.
    temperature: float, how frozen policies pick: 0 greedy (argmax), else a sample at this
      temperature (None: as the runner was built).
    side_cost: float weight (or bool), a template learner is also rewarded by this times the
      decrease of its template's ``side_cost`` (None or 0: never; fine-tuning turns it on).
    gamma: float, the discount per tick (None: the runner's ``gamma``); traced, so runs
      with different discounts share one compile (a sweep).
    """

    learner: jax.Array
    start: jax.Array
    learned: jax.Array
    teleport: jax.Array | None = None
    continue_episodes: jax.Array | None = None
    temperature: jax.Array | None = None
    side_cost: jax.Array | None = None
    gamma: jax.Array | None = None


class HierarchyRunner:
    """Compiles a hierarchy over an environment into batched tick/reset functions."""

    def __init__(self, env, env_params, hierarchy: Hierarchy, agent, *, gamma: float,
                 frozen_policy: str = "greedy", allow_teleport: bool = True,
                 reset_on_learner_end: bool = True, frozen_temperature: float = 1.0,
                 learner_acts_frozen: bool = False, reset_pool: int = 0,
                 frozen_eval: str = "auto"):
        if frozen_policy not in ("greedy", "sample"):
            raise ValueError(f"frozen_policy must be 'greedy' or 'sample', got {frozen_policy!r}")
        self.env, self.env_params, self.h, self.agent = env, env_params, hierarchy, agent
        check_success(hierarchy, env, env_params)
        self.gamma = float(gamma)
        self.frozen_policy = frozen_policy
        if not frozen_temperature > 0:
            raise ValueError(f"frozen_temperature must be > 0, got {frozen_temperature}")
        self.frozen_temperature = float(frozen_temperature)
        self.allow_teleport = bool(allow_teleport)
        self.reset_on_learner_end = bool(reset_on_learner_end)
        # The learner picks as the bank will run it once frozen (greedy or sampled, per
        # ``frozen_policy``) instead of exploring: the engine's level acceptance gate.
        self.learner_acts_frozen = bool(learner_acts_frozen)
        if isinstance(reset_pool, bool) or not isinstance(reset_pool, int) or reset_pool < 0:
            raise ValueError(f"reset_pool must be an integer >= 0, got {reset_pool!r}")
        self.reset_pool = reset_pool
        if frozen_eval not in FROZEN_EVALS:
            raise ValueError(f"frozen_eval must be one of {FROZEN_EVALS}, got {frozen_eval!r}")
        if frozen_eval == "auto":  # measured: benchmarks/RESULTS.md, section 8
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
        self.action_shape = tuple(space.shape)
        self.action_dtype = space.dtype
        self.teleport_families = _families([t.teleport for t in tpls])
        self.controller_families = _families([t.controller for t in tpls])

    # ---- per-environment template evaluations (unbatched) ------------------
    def _per_option(self, state, field: str, root, dtype) -> jax.Array:
        """[O]: ``root`` for the root option, then each template's ``field`` on ``state``
        (``root`` too where a template leaves that optional field unset)."""
        fns = [getattr(t, field) for t in self.templates]
        vals = [root] + [root if fn is None else fn(state, self.env_params) for fn in fns]
        return jnp.stack([jnp.asarray(v, dtype).reshape(()) for v in vals])

    def _satisfied(self, state) -> jax.Array:
        return self._per_option(state, "satisfied", False, bool)

    def _side_cost(self, state) -> jax.Array:
        return self._per_option(state, "side_cost", 0.0, jnp.float32)

    def _failed(self, state) -> jax.Array:
        return self._per_option(state, "failed", False, bool)

    def _initiation(self, state) -> jax.Array:
        return self._per_option(state, "initiation", True, bool)

    def teleports_on(self, controls: Controls) -> jax.Array:
        """bool: unlearned templates with a teleport jump (else they are not callable)."""
        allowed = jnp.asarray(self.allow_teleport)
        return allowed if controls.teleport is None else allowed & controls.teleport

    def callable_options(self, learned: jax.Array, learner: jax.Array,
                         teleport: jax.Array | bool | None = None) -> jax.Array:
        """bool [num_options]: options that can run now (learned, the learner, or realisable)."""
        ids = jnp.arange(self.h.num_options)
        teleport = self.allow_teleport if teleport is None else teleport
        realise = jnp.asarray(self.has_controller) | (jnp.asarray(self.has_teleport) & teleport)
        return learned | realise | (ids == learner)

    def action_masks(self, init_ok: jax.Array, callable_: jax.Array) -> jax.Array:
        """bool [num_options, A]: what each option may choose in this state."""
        call_ok = (init_ok & callable_)[1:]
        allowed = jnp.concatenate([jnp.ones((self.P,), bool), call_ok])
        return self.child_mask & allowed[None, :]

    # ---- resets -------------------------------------------------------------
    def reset(self, key: jax.Array, controls: Controls, num_envs: int) -> EnvCarry:
        # without a pool the key is used as it always was, so such runs keep their numbers
        k_envs, k_pool = jax.random.split(key) if self.reset_pool else (key, None)
        obs, state = self._fresh_starts(k_envs, num_envs)
        stack = jax.vmap(lambda _: stack_init(self.D, controls.start))(jnp.arange(num_envs))
        zeros_b = jnp.zeros((num_envs,), bool)
        pool = self._new_pool(k_pool) if self.reset_pool else None
        zeros_f = jnp.zeros((num_envs,), jnp.float32)
        return EnvCarry(state, obs, stack, zeros_b, zeros_f, zeros_f,
                        no_pending(obs, self.h.num_actions), pool)

    def _fresh_starts(self, key: jax.Array, n: int):
        return jax.vmap(self.env.reset_env, (0, None))(jax.random.split(key, n), self.env_params)

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

    # ---- the decision cascade (unbatched) -------------------------------------
    def _decide(self, stack, frozen_choice, learner_choice, controls: Controls, callable_):
        """Walk down from the stack top until a primitive step is fixed."""
        decided = jnp.asarray(False)
        learner_decided = jnp.asarray(False)
        primitive = jnp.asarray(0, jnp.int32)
        teleported = jnp.asarray(NO_OPTION, jnp.int32)
        scripted = jnp.asarray(NO_OPTION, jnp.int32)
        # A called template is pushed if it is learned, is the learner, or plays a scripted
        # controller (when it is not teleported instead); otherwise it is teleported.
        scripted_ok = jnp.asarray(self.has_controller) & ~(
            jnp.asarray(self.has_teleport) & self.teleports_on(controls))
        pushable = (controls.learned | (jnp.arange(self.h.num_options) == controls.learner)
                    | scripted_ok)
        for _ in range(self.D):
            top = jnp.maximum(stack_top(stack), 0)
            is_learner = top == controls.learner
            is_scripted = ~is_learner & ~controls.learned[top]
            choice = jnp.where(is_learner, learner_choice, frozen_choice[top])
            open_ = ~decided
            run_script = open_ & is_scripted
            chooses = open_ & ~is_scripted
            learner_decided = learner_decided | (chooses & is_learner)
            is_prim = choice < self.P
            tpl = jnp.clip(choice - self.P + 1, 0, self.h.num_options - 1)
            push = chooses & ~is_prim & pushable[tpl] & callable_[tpl]
            teleport = chooses & ~is_prim & ~push
            take_prim = chooses & is_prim
            scripted = jnp.where(run_script, top, scripted)
            primitive = jnp.where(take_prim, choice, primitive)
            teleported = jnp.where(teleport, tpl, teleported)
            decided = decided | run_script | take_prim | teleport
            stack = stack_push(stack, tpl, push)
        return stack, primitive, teleported, scripted, learner_decided

    # ---- one tick for the whole batch ------------------------------------------
    def tick(self, carry: EnvCarry, key: jax.Array, learner_state, bank_params,
             controls: Controls) -> tuple[EnvCarry, Transition, EpisodeEnds]:
        B = carry.obs.shape[0]
        k_act, k_frozen, k_ctrl, k_tp, k_step, k_reset = jax.random.split(key, 6)
        teleport_on = self.teleports_on(controls)
        callable_ = self.callable_options(controls.learned, controls.learner, teleport_on)
        init_ok = jax.vmap(self._initiation)(carry.env_state)                     # [B, O]
        masks = jax.vmap(lambda i: self.action_masks(i, callable_))(init_ok)      # [B, O, A]
        learner_idx = jnp.maximum(controls.learner, 0)
        learner_mask = masks[:, learner_idx]                                      # [B, A]
        if self.learner_acts_frozen:
            act = self._act_frozen(learner_state, carry.obs, learner_mask, k_act, controls)
        else:
            act = self.agent.act(learner_state, carry.obs, learner_mask, k_act)
        logits = self.frozen_logits(bank_params, carry.obs, controls)             # [O, B, A]
        logits = jnp.where(jnp.swapaxes(masks, 0, 1), logits, -1e9)
        frozen = self._frozen_pick(logits, k_frozen, controls)
        frozen = jnp.swapaxes(frozen, 0, 1).astype(jnp.int32)                     # [B, O]

        stack, primitive, teleported, scripted, decided = jax.vmap(
            lambda s, f, l: self._decide(s, f, l, controls, callable_)
        )(carry.stack, frozen, act.action)

        action = jnp.broadcast_to(
            primitive.reshape((B,) + (1,) * len(self.action_shape)), (B,) + self.action_shape
        ).astype(self.action_dtype)
        if self.controller_families:
            action = self._run_family(self.controller_families, k_ctrl, carry.env_state, scripted,
                                      action, controls=True)

        state_in = carry.env_state
        if self.allow_teleport and self.teleport_families:
            teleported = jnp.where(teleport_on, teleported, NO_OPTION)
            state_in, action = self._run_family(self.teleport_families, k_tp, state_in, teleported,
                                                action, controls=False)

        obs, state, reward, terminated, truncated, info = jax.vmap(
            self.env.step_env, (0, 0, 0, None)
        )(jax.random.split(k_step, B), state_in, action, self.env_params)

        # pops: the lowest entry that is satisfied or out of ticks ends, with all above it
        stack = jax.vmap(stack_tick)(stack)
        sat = jax.vmap(self._satisfied)(state)                                   # [B, O]
        stop = sat
        if any(t.failed is not None for t in self.templates):
            stop = sat | jax.vmap(self._failed)(state)
        opt = jnp.maximum(stack.option, 0)
        live = jnp.arange(self.D)[None, :] < stack.depth[:, None]
        ended = live & (jnp.take_along_axis(stop, opt, 1) | (stack.steps >= self.k_max[opt]))
        first_end = jnp.where(ended.any(1), jnp.argmax(ended, 1), self.D)
        learner_on = jax.vmap(stack_contains, (0, None))(stack, controls.learner)
        learner_pos = jnp.argmax(stack.option == controls.learner, 1)
        learner_ended = learner_on & (first_end <= learner_pos)
        stack = jax.vmap(stack_truncate)(stack, first_end)

        env_done = terminated | truncated
        task_end = env_done | (first_end == 0)
        reset = task_end | (learner_ended & self.resets_on_learner_end(controls))
        is_root = controls.learner <= 0
        learner_reward = jnp.where(
            is_root, reward.astype(jnp.float32),
            (learner_on & sat[:, learner_idx]).astype(jnp.float32),
        )
        tp_steps = jnp.where(teleported >= 0, self.nominal[jnp.maximum(teleported, 0)], 1.0)
        gamma = self.gamma if controls.gamma is None else controls.gamma
        discount = gamma ** tp_steps
        shaping = self._side_cost_shaping(carry.env_state, state, discount, learner_on,
                                          learner_idx, is_root, controls)
        # In evaluation (no learner) the whole episode counts, with the environment's reward.
        started = carry.learner_started | decided | (controls.learner < 0)
        ep_return = carry.learner_return + jnp.where(started, learner_reward, 0.0)
        task_return = carry.task_return + reward.astype(jnp.float32)
        # The learner's episode is one run of its option: it ends with the environment's
        # episode or when the option ends (the same tick unless episodes continue).
        learner_done = reset | learner_ended
        finished = learner_done & started

        obs_re, state_re, pool = self._next_starts(carry, reset, k_reset)
        fresh = jax.vmap(lambda _: stack_init(self.D, controls.start))(jnp.arange(B))
        new_carry = EnvCarry(
            env_state=jax.vmap(select_tree)(reset, state_re, state),
            obs=jax.vmap(select_tree)(reset, obs_re, obs),
            stack=jax.vmap(select_tree)(reset, fresh, stack),
            learner_started=started & ~learner_done,
            learner_return=jnp.where(learner_done, 0.0, ep_return),
            task_return=jnp.where(reset, 0.0, task_return),
            pending=carry.pending,  # the engine updates it once per rollout (carry_pending)
            pool=pool,
        )
        transition = Transition(
            obs=carry.obs, action=act.action, action_mask=learner_mask, log_prob=act.log_prob,
            value=act.value, decision=decided,
            reward=jnp.where(started, learner_reward + shaping, 0.0),
            discount=discount, done=learner_done,
        )
        # Success of a finished episode: the template's F_o (its return) for a template
        # learner; for the root, the task's success (task_success), else the episode return.
        task_success = self.task_success(state, info)
        if task_success is not None:
            success = jnp.where(is_root, task_success, ep_return)
        else:
            task_success, success = task_return, ep_return
        # A whole-task episode counts where the root is at the bottom of the stack and the
        # episode ended by itself (not cut because a learner's option ended).
        task_end = task_end & (controls.start == 0)
        ends = EpisodeEnds(
            reset=reset, finished=finished, ret=jnp.where(finished, ep_return, 0.0),
            success=jnp.where(finished, success, 0.0), decided=decided,
            task_end=task_end, task_success=jnp.where(task_end, task_success, 0.0),
        )
        return new_carry, transition, ends

    def task_success(self, state, info: dict) -> jax.Array | None:
        """[B] float: the root's success of episodes ending in ``state`` (batched): the
        hierarchy's declared ``success(state, params)``, else the environment's
        ``info["success"]`` (e.g. Fetch's fraction of blocks placed); None where neither
        exists (the episode return is the success then)."""
        if self.h.success is not None:
            value = jax.vmap(self.h.success, (0, None))(state, self.env_params)
            return jnp.asarray(value, jnp.float32).reshape(-1)  # scalar or [1] per state
        if "success" in info:
            return jnp.asarray(info["success"], jnp.float32)
        return None

    def _side_cost_shaping(self, before, after, discount, learner_on, learner_idx, is_root,
                           controls: Controls):
        """A template learner's extra reward ``c(s) - discount * c(s')`` for its template's
        ``side_cost`` c, times the weight ``controls.side_cost`` (0 elsewhere). Summed over
        the option's run it telescopes to minus the discounted cost it ends with, above what
        it started with."""
        if controls.side_cost is None or not any(t.side_cost is not None for t in self.templates):
            return 0.0
        c0 = jax.vmap(self._side_cost)(before)[:, learner_idx]
        c1 = jax.vmap(self._side_cost)(after)[:, learner_idx]
        weight = jnp.asarray(controls.side_cost, jnp.float32)
        return jnp.where(learner_on & ~is_root, weight * (c0 - discount * c1), 0.0)

    def _act_frozen(self, learner_state, obs, mask, key, controls: Controls) -> ActOutput:
        """The learner picks as the bank will run it once frozen (the level's gate); with no
        learner (evaluation) its network is not run at all."""
        def own():
            return self.agent.policy_logits(learner_state.params, obs)

        shape = jax.eval_shape(own)
        logits = jax.lax.cond(controls.learner >= 0, own,
                              lambda: jnp.zeros(shape.shape, shape.dtype))
        action = self._frozen_pick(jnp.where(mask, logits, -1e9), key, controls).astype(jnp.int32)
        zeros = jnp.zeros(action.shape, jnp.float32)
        return ActOutput(action, zeros, zeros)

    def frozen_logits(self, bank_params, obs: jax.Array, controls: Controls) -> jax.Array:
        """[O, B, A] scores of the frozen policies that can decide now: the learned options
        other than the learner (the rest are never read and stay 0).

        ``frozen_eval="learned"``: a loop over just those options, not a vmap over the
        whole bank: in top-down training most of the bank is not learned yet (level 1: none
        of it), and a policy's first layer on a wide observation is the tick's largest cost
        on a CPU. Under a ``vmap`` over seeds the loop runs as often as the seed with the
        most learned options needs. ``"all"``: one batched apply over the whole bank (on a
        GPU one wide kernel costs less than a loop of small ones); the unneeded rows are
        computed but never read.
        """
        if self.frozen_eval == "all":
            return jax.vmap(self.agent.policy_logits, (0, None))(bank_params, obs)
        num_options = self.h.num_options
        need = controls.learned & (jnp.arange(num_options) != controls.learner)
        order = jnp.argsort(~need)  # the needed option ids first (argsort is stable)
        first = jax.tree.map(lambda p: p[0], bank_params)
        shape = jax.eval_shape(self.agent.policy_logits, first, obs)
        out = jnp.zeros((num_options,) + shape.shape, shape.dtype)

        def one(i, out):
            option = order[i]
            params = jax.tree.map(lambda p: p[option], bank_params)
            return out.at[option].set(self.agent.policy_logits(params, obs))

        return jax.lax.fori_loop(0, need.sum(), one, out)

    def frozen_temperature_of(self, controls: Controls) -> jax.Array | float:
        """The temperature frozen policies pick at (0: greedy)."""
        if controls.temperature is not None:
            return controls.temperature
        return 0.0 if self.frozen_policy == "greedy" else self.frozen_temperature

    def resets_on_learner_end(self, controls: Controls) -> jax.Array | bool:
        """Whether an environment is reset when the learner's option ends."""
        if controls.continue_episodes is None:
            return self.reset_on_learner_end
        return ~controls.continue_episodes

    def _frozen_pick(self, logits: jax.Array, key: jax.Array, controls: Controls) -> jax.Array:
        """A frozen policy's choice from masked scores (last axis): argmax at temperature 0,
        else a sample at the temperature."""
        temperature = self.frozen_temperature_of(controls)
        if isinstance(temperature, float):  # known when tracing: compute only that pick
            if temperature == 0.0:
                return jnp.argmax(logits, -1)
            return jax.random.categorical(key, logits / temperature, -1)
        sample = jax.random.categorical(key, logits / jnp.maximum(temperature, 1e-6), -1)
        return jnp.where(temperature > 0, sample, jnp.argmax(logits, -1))

    def _run_family(self, families, key, state, chosen, action, *, controls: bool):
        """Realise the template ``chosen[b]`` (option id, -1 for none) of each environment.

        One vmapped call per family: a family's data is gathered per environment for the
        member it runs. Controllers return an action; teleports a (state, action) pair.
        """
        B = chosen.shape[0]
        safe = jnp.maximum(chosen, 0)
        for i, fam in enumerate(families):
            keys = jax.random.split(jax.random.fold_in(key, i), B)
            member = jnp.asarray(fam.member_of)[safe]
            hit = (chosen >= 0) & jnp.asarray(fam.is_member)[safe]
            data = jax.tree.map(lambda d: jnp.asarray(d)[member], fam.data)
            out = jax.vmap(fam.fn, (0, 0, None, 0))(keys, state, self.env_params, data)
            if controls:
                new_action = out
            else:
                jumped, new_action = out
                state = jax.vmap(select_tree)(hit, jumped, state)
            new_action = jnp.asarray(new_action, self.action_dtype).reshape(action.shape)
            action = jnp.where(hit.reshape((B,) + (1,) * (action.ndim - 1)), new_action, action)
        return action if controls else (state, action)


@dataclass(frozen=True)
class _Family:
    fn: Any
    data: Any             # stacked member data, leading axis = member
    member_of: np.ndarray  # [num_options] -> member index (0 where not a member)
    is_member: np.ndarray  # [num_options] bool


def _families(realisations) -> list[_Family]:
    """Group templates' teleports (or controllers) into families sharing one function.

    ``Parametric`` realisations with the same ``fn`` form one family; any other callable
    is a family of one (with no data). Option ids are template index + 1 (0 is the root).
    """
    groups: dict[int, list] = {}
    order: list[int] = []
    for j, real in enumerate(realisations, start=1):
        if real is None:
            continue
        fn = real.fn if isinstance(real, Parametric) else real
        if id(fn) not in groups:
            groups[id(fn)] = []
            order.append(id(fn))
        groups[id(fn)].append((j, real))
    out = []
    n = len(realisations) + 1
    for gid in order:
        members = groups[gid]
        first = members[0][1]
        member_of, is_member = np.zeros(n, np.int32), np.zeros(n, bool)
        for m, (j, _) in enumerate(members):
            member_of[j], is_member[j] = m, True
        if isinstance(first, Parametric):
            data = jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]),
                                *[r.data for _, r in members])
            fn = first.fn
        else:
            data, fn = np.zeros((1,), np.int32), _drop_data(first)
        out.append(_Family(fn, data, member_of, is_member))
    return out


def _drop_data(fn):
    def call(key, state, params, _data):
        return fn(key, state, params)
    return call
