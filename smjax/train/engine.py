"""The compiled core shared by every method: level chunks, the policy bank, evaluation.

One compiled ``chunk`` serves every level of every method: the option being trained,
the option each episode starts from and the set of learned options are traced
arrays, and every learner has the same padded action head (all primitives + all
templates, masked per option). Seeds are a leading axis: side by side (``vmap``) on a
GPU or several devices, one after another on one CPU device (``over_seeds``).
"""
from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from smjax.agents.option_batch import joint_batch, options_update
from smjax.agents.smdp import carry_pending
from smjax.core.env import over_seeds, select_tree
from smjax.options.bank import frozen_temperature
from smjax.options.hierarchy import Hierarchy
from smjax.options.episodes import (  # noqa: F401 - EVAL_TEMPERATURES re-exported
    EVAL_TEMPERATURES, SEED_AXES, SKIP, early_stop_bounds, eval_temperatures, seed_batched_episodes)
from smjax.options.runner import NO_OPTION, Controls, EnvCarry, HierarchyRunner, TickStats
from smjax.train.ahead import CompileAhead
from smjax.train.config import TrainConfig
from smjax.train.episode_calls import EpisodeCalls
from smjax.train.learner import check_same_state
from smjax.train.program_cache import SavedOnFirstCall, compile_program
from smjax.train.seed_arrays import finite_flag
from smjax.train.seed_threads import ALL_SEED_AXES, Busy, SeedGroups, thread_count


# a chunk's seeds that train: its ``active`` argument (an idle seed keeps its state)
CHUNK_BUSY = Busy(position=1, when=True, droppable=False)
# an episodes program's due seeds: not ``skip`` (a skipped seed's results are meaningless)
EPISODES_BUSY = Busy(position=SKIP, when=False, droppable=True)


def _same(x):
    return x


class SeedState(NamedTuple):
    carry: EnvCarry
    learner: Any
    key: jax.Array


class ChunkControls(NamedTuple):
    """One seed's traced settings of a level chunk (each a per-seed array under ``chunk``),
    the ``Controls`` of its ticks: ``learner``, the option trained; ``start``, the option
    episodes start from; ``teleport``: options not learned yet are teleported (levels) or
    not (fine-tuning turns); ``continue_episodes``: episodes go on when the learner's
    option ends; ``side_cost``: the weight of the templates' side cost in the learner's
    reward; ``gamma``: the learner's discount (traced: a sweep over it compiles once)."""

    learner: Any
    start: Any
    teleport: Any
    continue_episodes: Any
    side_cost: Any
    gamma: Any


class Engine:
    """Builds the jitted functions over seeds for one (env, hierarchy, agent, config)."""

    def __init__(self, env, env_params, hierarchy: Hierarchy, agent, cfg: TrainConfig,
                 joint_agent=None):
        self.env, self.env_params, self.h, self.agent, self.cfg = env, env_params, hierarchy, agent, cfg
        # the learner whose update joint fine-tuning runs (``learner.make_joint_learner``)
        self.joint_agent = agent if joint_agent is None else joint_agent
        # how frozen policies act: the config's choice, else what the learner declares
        self.frozen_policy = mode = (agent.frozen_policy if cfg.frozen_policy == "auto"
                                     else cfg.frozen_policy)
        # The ticks' settings from the config, computed once and passed in every
        # ``Controls``: the discount, and the temperature frozen policies pick at. One
        # runner serves training, the gate and evaluation; the gate and evaluation run the
        # learner as it will be frozen (``acts_frozen``) with teleports as a traced switch
        # (the gate: the level's own; evaluation: none), so both share one program.
        self.gamma = float(cfg.gamma)
        self.temperature = frozen_temperature(mode, cfg.option_temperature,
                                              hierarchy.num_options)
        # the runner's structure (a saved policy rebuilds its runner from these)
        run = cfg.run
        self.runner_settings = dict(reset_pool=run.pool_size, frozen_eval=run.frozen_eval,
                                    policy_memory=run.policy_memory)
        self.runner = HierarchyRunner(env, env_params, hierarchy, agent, **self.runner_settings)
        # what the policies see: a learner's init reads only its shape and dtype (traced)
        obs = jax.eval_shape(self._example_obs, jax.random.PRNGKey(0), env_params)
        self.example_obs = np.zeros(obs.shape, obs.dtype)
        self.num_actions = hierarchy.num_actions
        # every argument has a seed axis: each seed trains its own level (or fine-tunes),
        # side by side, or one after another where compute is serial (one CPU device):
        # there a seed's work ends with its own, and an idle seed costs nothing
        self.seed_by_seed = jax.default_backend() == "cpu" and jax.device_count() == 1
        seeds = functools.partial(over_seeds, one_after_another=self.seed_by_seed)
        # and there the chunks and episodes run groups of seeds on threads of their own
        self.seed_threads = thread_count(self.seed_by_seed)
        self.chunk = jax.jit(seeds(self.seed_chunk), donate_argnums=(0,))
        self.joint_chunk = jax.jit(seeds(self._joint_chunk), donate_argnums=(0,))
        # the gate's and the evaluation's episodes, one program
        self.episodes = seed_batched_episodes(self.runner, self.gamma, self.seed_by_seed)
        self.episode_calls = EpisodeCalls(self.compile_episodes, not self.seed_by_seed)
        # what keys this engine's programs in the program cache (None: not cached); the
        # run sets it where the task and config name everything the programs depend on
        self.program_identity: dict | None = None
        # the learners' init's: the program identity and the traced hyper-parameters' values,
        # which the init writes into the learners' state
        self.init_identity: dict | None = None
        # the start-up's programs (the init, the reset below), loaded untraced by a repeated
        # run as the chunks are
        self._init = SavedOnFirstCall(
            jax.jit(seeds(lambda k: agent.init(k, self.example_obs, self.num_actions))),
            "init", identity_of=lambda: self.init_identity)
        if self.joint_agent is not agent:
            check_same_state(agent, self.joint_agent, self.example_obs, self.num_actions)
        # host-side array plumbing as one program each, not one tiny program per leaf
        self._per_option = jax.jit(self._copies_per_option)
        self._warm = jax.jit(jax.vmap(agent.warm_start))
        self._warm_joint = jax.jit(lambda learners, bank: jax.vmap(jax.vmap(agent.warm_start))(
            self._copies_per_option(learners), bank))
        # jitted, so it also slices a bank sharded over processes
        self._bank_entry0 = jax.jit(lambda bank: jax.tree.map(lambda p: p[:, 0], bank))
        self.reset = SavedOnFirstCall(jax.jit(jax.vmap(self._reset)), "reset",  # keys, starts [S]
                                      identity_of=lambda: self.program_identity)
        # the same episodes for a new learner (a fine-tuning turn's): leading axis S
        self.hand_over = jax.jit(jax.vmap(self.runner.hand_over))

    def compile(self, name: str, jitted, args: tuple, static: tuple = (), donate: tuple = (),
                seed_axes: tuple | None = ALL_SEED_AXES, busy: Busy | None = None):
        """``jitted`` compiled for ``args``, without tracing where an earlier run saved the
        same program and ``program_identity`` names everything it depends on
        (:mod:`smjax.train.program_cache`); where seeds run in groups on threads
        (:mod:`smjax.train.seed_threads`; ``seed_axes``: which arguments have a seed axis;
        ``busy``: which seeds of a call have work), compiled for one group and called on
        each."""
        groups = SeedGroups.for_program(self.seed_threads, args, seed_axes, busy)
        if groups is None:
            return compile_program(jitted, args, name, self.program_identity, static, donate)
        program = compile_program(jitted, groups.shapes(args), name, self.program_identity,
                                  static, donate)
        return groups.program(program)

    @property
    def success_bounded(self) -> bool:
        """The root's success lies in [0, 1]: the environment says so, or the hierarchy
        declares its success (documented to be a float in [0, 1] or a bool)."""
        return bool(self.env.success_in_unit_interval or self.h.success is not None)

    @property
    def root_has_threshold(self) -> bool:
        """The root's success can end a level at a threshold: not a return on no known scale
        (``Environment.success_unbounded``), or the hierarchy declares its success."""
        return bool(not self.env.success_unbounded or self.h.success is not None)

    # ---- state -----------------------------------------------------------------
    def init_learner(self, keys: jax.Array):
        """Fresh learner states for each seed (leading axis S), in one program: on one CPU
        device the seeds one after another (the numbers of one init per seed; XLA:CPU
        (jaxlib 0.10) can deadlock in ``jit(vmap(init))`` of these networks without the
        scheduler flag that ``smjax/__init__.py`` sets, and a user may opt out of it), side
        by side elsewhere (one init per seed from a host loop cost a 100-seed GPU run ~30 s)."""
        return self._init(keys)

    def warm_start(self, states, params):
        """Learner states (leading axis S) that continue from trained ``params``."""
        return self._warm(states, params)

    def _reset(self, key: jax.Array, start: jax.Array) -> EnvCarry:
        controls = Controls(jnp.asarray(NO_OPTION), start, jnp.zeros((self.h.num_options,), bool),
                            gamma=self.gamma, temperature=self.temperature)
        return self.runner.reset(key, controls, self.cfg.run.num_envs)

    def joint_state(self, learners, bank, reset_keys: jax.Array, keys: jax.Array) -> SeedState:
        """Joint fine-tuning's start, per seed (leading axis S): a learner per option
        (axis O), each continuing from its bank entry (``learners``: fresh states [S], e.g.
        with fine-tuning's hyper-parameters, copied once per option), fresh whole-task
        episodes from the root, and no pending decisions (one record per option)."""
        learners = self._warm_joint(learners, bank)
        carry = self.reset(reset_keys, np.zeros(reset_keys.shape[:1], np.int32))
        return SeedState(carry.replace(pending=self._per_option(carry.pending)),
                         learners, keys)

    def new_bank(self, learner_states) -> Any:
        """Policy bank per seed: [S, num_options, ...] copies of the learners' initial params."""
        return self._per_option(learner_states.params)

    def _copies_per_option(self, tree):
        """Each leaf [S, ...] as [S, num_options, ...] copies."""
        n = self.h.num_options
        return jax.tree.map(lambda x: jnp.repeat(x[:, None], n, axis=1), tree)

    def _example_obs(self, key: jax.Array, env_params) -> jax.Array:
        obs, _ = self.env.reset_env(key, env_params)
        return self.runner.policy_obs(obs[None])[0]

    # ---- one compiled chunk: updates_per_chunk x (rollout + update) ---------------
    def seed_chunk(self, state: SeedState, active, bank, learned, tick: ChunkControls,
                   windows=None, sizes=None):
        """One seed's chunk (``chunk`` is this over seeds, compiled).

        ``active``: whether the seed trains (the others keep their state); ``bank``: the
        frozen policies; ``learned``: bool [O], the options in the bank; ``tick``: the
        level's settings (teleports on, episodes reset with the learner's option unless
        ``TrainConfig.continue_episodes``, no side-cost shaping) or a fine-tuning turn's
        (the learned hierarchy alone, whole task episodes, side costs as
        ``TrainConfig.finetune_side_cost`` says).

        ``windows``: the seed's running-success windows (learner's, task's:
        ``state.SuccessWindow``), ``sizes``: their sizes in episodes (int32 [2]; a task size
        of 0: the seed is not fine-tuning, its task window is left as it is). Each update's
        batch goes in, and the chunk also returns, per update, each window's batch totals
        (newest first) and episodes (0 while not full); the host reduces them in float64
        (``SuccessWindow.push`` says why). Without ``windows`` (a benchmark timing the chunk
        alone) those outputs are None. The last says if the learner's params are finite."""
        controls = Controls(tick.learner, tick.start, learned, gamma=tick.gamma,
                            teleport=tick.teleport, continue_episodes=tick.continue_episodes,
                            temperature=self.temperature, side_cost=tick.side_cost)
        return self._updates(state, active, controls, bank, self._learn, windows, sizes)

    def _joint_chunk(self, state: SeedState, active, learned, side_cost, gamma, windows,
                     sizes):
        """Joint fine-tuning's chunk: ``state.learner`` holds a learner per option
        (leading axis O, warm-started from the bank: ``joint_state``), every learned
        option explores through its own and learns from its own record of every tick
        (``smjax.options.joint``); the learned hierarchy alone (no teleports), whole-task
        episodes from the root. ``gamma``: float [O], each option's discount. The other
        arguments and the outputs are ``seed_chunk``'s (the learner metrics per option:
        [U, O])."""
        controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0, jnp.int32), learned,
                            gamma=gamma, teleport=jnp.asarray(False),
                            continue_episodes=jnp.asarray(False), temperature=self.temperature,
                            side_cost=side_cost, acts_frozen=True, joint=True)
        return self._updates(state, active, controls, None, self._learn_joint, windows, sizes)

    def _update(self, learner, pending, traj, key):
        """One learner's update on a rollout; (learner, its new pending decisions, metrics):
        decisions whose option still runs train in the next rollout, once complete."""
        traj, pending = carry_pending(pending, traj)
        learner, metrics = self.agent.update(learner, traj, key)
        return learner, pending, metrics

    def _learn(self, learner, carry: EnvCarry, traj, key):
        """The learner's update on a rollout (its pending decisions carried over)."""
        learner, pending, metrics = self._update(learner, carry.pending, traj, key)
        return learner, carry.replace(pending=pending), metrics

    def _learn_joint(self, learners, carry: EnvCarry, traj, key):
        """Every option's update on its own rows of the rollout and pending decisions
        (``carry.pending``: axis O), in one ``update_options`` (the agent's, or per option);
        values the rollout left to ``option_values`` first, before pending rows carry them."""
        if self.agent.option_values is not None:
            traj = traj._replace(value=self.agent.option_values(learners, traj.obs,
                                                                traj.decision))
        batch, pending = joint_batch(carry.pending, traj)
        learners, metrics = options_update(self.joint_agent)(learners, batch, key)
        return learners, carry.replace(pending=pending), metrics

    def _updates(self, state: SeedState, active, controls: Controls, bank, learn, windows,
                 sizes):
        """``updates_per_chunk`` x (rollout + ``learn``) under ``controls``, and the
        running-success windows (``seed_chunk`` says what goes in and out)."""
        runner, cfg = self.runner, self.cfg

        def update_step(c, _):
            st, win = c
            key, k_roll, k_upd = jax.random.split(st.key, 3)
            carry = st.carry
            if runner.reset_pool:  # fresh episode starts for this rollout
                carry = runner.refill(carry, jax.random.fold_in(k_roll, 1))
                k_roll = jax.random.fold_in(k_roll, 0)

            def tick_fn(c, k):
                c, tr, ends = runner.tick(c, k, st.learner, bank, controls)
                return c, (tr, TickStats.of(ends))

            carry, (traj, stats) = jax.lax.scan(
                tick_fn, carry, jax.random.split(k_roll, cfg.run.rollout_ticks))
            learner_state, carry, metrics = learn(st.learner, carry, traj, k_upd)
            stats = jax.tree.map(lambda x: x.sum(0), stats)
            running = None
            if win is not None:
                tuning = sizes[1] > 0
                learner_win, learner_out = win[0].push(
                    stats.learner_success, stats.learner_episodes, sizes[0])
                task_win, task_out = win[1].push(
                    stats.task_success, jnp.where(tuning, stats.task_episodes, 0), sizes[1])
                win, running = (learner_win, task_win), (learner_out, task_out)
            return (SeedState(carry, learner_state, key), win), (stats, metrics, running)

        def train():
            (new, new_windows), (stats, metrics, running) = jax.lax.scan(
                update_step, (state, windows), None, cfg.run.updates_per_chunk)
            return new, stats, metrics, new_windows, running

        def keep(shapes):  # an idle seed: its state and windows as they were, nothing counted
            zeros = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)
            return state, zeros[1], zeros[2], windows, zeros[4]

        if self.seed_by_seed:  # an idle seed skips the work
            out = jax.lax.cond(active, train, lambda: keep(jax.eval_shape(train)))
        else:  # side by side (a cond would run both branches): computed and dropped
            trained = train()
            out = select_tree(active, trained, keep(trained))
        new, stats, metrics, new_windows, running = out
        return new, stats, metrics, new_windows, running, finite_flag(new.learner.params)

    # ---- gate and evaluation: one episode per environment, the first to finish ----------
    def episodes_ahead(self, args: tuple, num_envs: int, ahead: CompileAhead) -> None:
        """Compile the episodes program for these arguments (``gate_args`` or
        ``evaluate_args``) on ``ahead``'s thread, unless it is compiled or under way."""
        self.episode_calls.ahead(args, num_envs, ahead)

    def compile_episodes(self, args: tuple, num_envs: int):
        """The episodes program compiled for ``args`` (``gate_args`` or ``evaluate_args``)."""
        return self.compile(f"episodes-{num_envs}", self.episodes, args, static=(num_envs,),
                            seed_axes=SEED_AXES, busy=EPISODES_BUSY)

    def _seed_temperatures(self, policy: str, num_seeds: int) -> jax.Array:
        """float32 [S, O]: each option's temperature under ``policy``, for every seed (a
        per-seed input, so a mesh splits it along its seed axis like the others)."""
        t = eval_temperatures(policy, self.h.num_options, self.cfg.option_temperature)
        return jnp.broadcast_to(t, (num_seeds,) + t.shape)

    def evaluate(self, *args, **kwargs) -> tuple[dict, float]:
        """``evaluate_args``' episodes: their result and the seconds spent compiling."""
        return self.episode_calls(self.evaluate_args(*args, **kwargs),
                                  self.cfg.evaluation.eval_envs)

    def evaluate_args(self, keys, bank, learned, learner_state=None, place=_same, *,
                      policy: str | None = None, due: list[bool] | None = None,
                      threshold: float | None = None) -> tuple:
        """The trained hierarchy alone (root on the stack, no teleports, nobody learning),
        ``eval_envs`` episodes per seed. ``policy``: how frozen policies pick ("greedy",
        "sample"; None: the run's frozen policy). ``due``: the seeds to evaluate (others
        are skipped, their results meaningless). ``threshold``: stop a seed's episodes once
        reaching it or not is certain (a gate; needs task successes in [0, 1]). ``place``
        puts the small per-call inputs where the caller's mesh needs them (every input
        must be global across processes). ``learner_state`` is not needed (nobody learns in
        evaluation); where given, only its params are passed (they are never run)."""
        S = keys.shape[0]
        policy = self.frozen_policy if policy is None else policy
        due = [True] * S if due is None else due
        bounded = threshold is not None and self.success_bounded
        decide = early_stop_bounds([threshold if bounded else None] * S)
        per_seed = place((jnp.full((S,), NO_OPTION, jnp.int32), jnp.zeros((S,), jnp.int32),
                          ~jnp.asarray(due, bool), decide, self._seed_temperatures(policy, S)))
        teleport, max_ticks = place((jnp.asarray(False), jnp.asarray(self.cfg.evaluation.eval_max_ticks)))
        learner, start, skip, decide, temperatures = per_seed
        # the program (shared with the gate) takes learner params; with none, option 0's
        # bank entry has their shapes (the bank is built from the learners' params)
        params = self._bank_entry0(bank) if learner_state is None else learner_state.params
        return (keys, params, bank, learned, learner, start, teleport, temperatures, max_ticks,
                skip, decide)

    def gate(self, *args, **kwargs) -> tuple[dict, float]:
        """``gate_args``' episodes: their result and the seconds spent compiling."""
        return self.episode_calls(self.gate_args(*args, **kwargs), self.cfg.evaluation.gate_envs)

    def gate_args(self, keys, state: SeedState, bank, learned, learners: list[int],
                  starts: list[int], due: list[bool], thresholds: list[float],
                  place=_same) -> tuple:
        """Each seed's learner as it will be frozen, called where the levels above call it
        (``keys``: per seed, varied between attempts by the caller; a seed not ``due`` is
        skipped); a seed's episodes stop once passing its threshold or not is certain."""
        # a template's success is its F_o (0 or 1); the root's is the task's
        bounded = [o != 0 or self.success_bounded for o in learners]
        decide = early_stop_bounds([t if b else None for t, b in zip(thresholds, bounded)])
        per_seed = place((jnp.asarray(learners, jnp.int32), jnp.asarray(starts, jnp.int32),
                          ~jnp.asarray(due, bool), decide,
                          self._seed_temperatures(self.frozen_policy, len(learners))))
        teleport, max_ticks = place((jnp.asarray(True), jnp.asarray(self.cfg.evaluation.gate_max_ticks)))
        learner, start, skip, decide, temperatures = per_seed
        return (keys, state.learner.params, bank, learned, learner, start, teleport, temperatures,
                max_ticks, skip, decide)
