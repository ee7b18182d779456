"""The tick's cost cuts keep its meaning: frozen policies only where they can decide, episode
starts from a pool, gates that stop once their answer is certain, the compilation cache."""
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hier_env import KeyDoor, make_keydoor
from smjax.agents import make_agent
from smjax.options.runner import Controls, HierarchyRunner
from smjax.train.config import TrainConfig
from smjax.options.episodes import early_stop_bounds, seed_batched_episodes
from smjax.train.ahead import CompileAhead
from smjax.train.engine import ChunkControls, Engine, SeedState
from smjax.train.episode_calls import EpisodeCalls
from smjax.core.env import over_seeds

ROOT = Path(__file__).resolve().parents[1]


def _runner(reset_pool: int = 0):
    env = KeyDoor()
    h = env.hierarchies()["paper"]
    agent = make_agent("ppo", hidden_sizes=(16,))
    return env, h, agent, HierarchyRunner(env, env.default_params, h, agent,
                                          reset_pool=reset_pool)


_ENV, _H, _AGENT, _RUNNER = _runner()
_OBS = _ENV.reset_env(jax.random.PRNGKey(0), _ENV.default_params)[0]
_BANK = jax.vmap(lambda k: _AGENT.init(k, _OBS, _H.num_actions).params)(
    jax.random.split(jax.random.PRNGKey(1), _H.num_options))
_FROZEN = jax.jit(lambda bank, obs, learned, learner: _RUNNER.frozen_logits(
    bank, obs, Controls(learner, jnp.asarray(0), learned, gamma=0.9)))


@settings(max_examples=12, deadline=None)
@given(learned=st.lists(st.booleans(), min_size=2, max_size=2), learner=st.sampled_from([-1, 0, 1]))
def test_frozen_logits_equal_the_whole_bank_where_an_option_can_decide(learned, learner):
    obs = jax.vmap(lambda k: _ENV.reset_env(k, _ENV.default_params)[0])(
        jax.random.split(jax.random.PRNGKey(2), 5))
    got = np.asarray(_FROZEN(_BANK, obs, jnp.asarray(learned), jnp.asarray(learner)))
    full = np.asarray(jax.vmap(_AGENT.policy_logits, (0, None))(_BANK, obs))
    for option in range(_H.num_options):
        if learned[option] and option != learner:
            np.testing.assert_allclose(got[option], full[option], rtol=1e-5, atol=1e-6)
        else:  # never read by the tick, and not computed
            assert (got[option] == 0).all()


def test_reset_pool_hands_out_each_start_once_before_reusing():
    env, h, agent, runner = _runner(reset_pool=5)
    controls = Controls(jnp.asarray(0), jnp.asarray(0), jnp.zeros((2,), bool), gamma=0.9)
    carry = runner.reset(jax.random.PRNGKey(0), controls, 4)
    pool_pos = np.asarray(carry.pool.state.pos)
    reset = jnp.asarray([True, False, True, True])
    obs, state, pool = runner._next_starts(carry, reset, jax.random.PRNGKey(1))
    np.testing.assert_array_equal(np.asarray(state.pos)[[0, 2, 3]], pool_pos[[0, 1, 2]])
    assert int(pool.next) == 3
    carry = carry.replace(pool=pool)
    obs, state, pool = runner._next_starts(carry, jnp.asarray([True, True, True, False]),
                                           jax.random.PRNGKey(2))
    # slots 3, 4, then the pool wraps around to its first start
    np.testing.assert_array_equal(np.asarray(state.pos)[:3], pool_pos[[3, 4, 0]])
    assert int(pool.next) == 1
    refilled = runner.refill(carry.replace(pool=pool), jax.random.PRNGKey(3))
    assert int(refilled.pool.next) == 0


def _engine(threshold_cfg: TrainConfig) -> tuple[Engine, SeedState]:
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    engine = Engine(env, params, h, make_agent("ppo", hidden_sizes=(16,)), threshold_cfg)
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    learner = engine.init_learner(keys)
    state = SeedState(engine.reset(keys, jnp.zeros((3,), jnp.int32)), learner, keys)
    return engine, state


def test_gate_stops_early_with_the_same_decision():
    cfg = TrainConfig(num_envs=8, gate_envs=32, gate_max_ticks=200)
    engine, state = _engine(cfg)
    bank = engine.new_bank(state.learner)
    learned = jnp.zeros((3, engine.h.num_options), bool)
    keys = jax.random.split(jax.random.PRNGKey(5), 3)
    due = [True] * 3
    for threshold in (0.05, 0.3, 0.6, 0.95):
        # the key-door return is 1 for an opened door, else 0: a success in [0, 1]
        engine.env.success_in_unit_interval = True
        early, _ = engine.gate(keys, state, bank, learned, [0] * 3, [0] * 3, due, [threshold] * 3)
        # the same episodes without stopping early (as for an unbounded success range)
        engine.env.success_in_unit_interval = False
        full, _ = engine.gate(keys, state, bank, learned, [0] * 3, [0] * 3, due, [threshold] * 3)
        np.testing.assert_array_equal(np.asarray(early["success"]) >= threshold,
                                      np.asarray(full["success"]) >= threshold)
        assert (np.asarray(early["env_steps"]) <= np.asarray(full["env_steps"])).all()


def test_seeds_one_after_another_give_each_seed_what_side_by_side_gives():
    """A CPU runs the episodes program's seeds one after another: each seed's numbers are
    those of the seeds side by side, and a skipped seed reports no env steps."""
    cfg = TrainConfig(num_envs=8, gate_envs=16, gate_max_ticks=60)
    engine, state = _engine(cfg)
    bank = engine.new_bank(state.learner)
    learned = jnp.zeros((3, engine.h.num_options), bool).at[:, 0].set(True)
    keys = jax.random.split(jax.random.PRNGKey(7), 3)
    results = {}
    for one_at_a_time in (False, True):
        engine.episodes = seed_batched_episodes(engine.runner, engine.gamma, one_at_a_time)
        engine.episode_calls.compiled = {}
        for due in ([True] * 3, [False, True, False]):
            results[one_at_a_time, sum(due)], _ = engine.gate(
                keys, state, bank, learned, [1] * 3, [0] * 3, due, [0.8] * 3)
    for name in results[False, 3]:
        np.testing.assert_array_equal(results[False, 3][name], results[True, 3][name])
        np.testing.assert_array_equal(np.asarray(results[False, 1][name])[1],
                                      np.asarray(results[True, 1][name])[1])
    assert (np.asarray(results[True, 1]["env_steps"]) > 0).tolist() == [False, True, False]


def _chunk(engine, state, active, one_after_another):
    S = len(active)
    tick = ChunkControls(jnp.zeros(S, jnp.int32), jnp.zeros(S, jnp.int32), jnp.ones(S, bool),
                         jnp.zeros(S, bool), jnp.zeros(S), jnp.full(S, 0.99))
    engine.seed_by_seed = one_after_another  # side by side: an idle seed's work is dropped
    chunk = jax.jit(over_seeds(engine.seed_chunk, one_after_another))
    return chunk(state, jnp.asarray(active), engine.new_bank(state.learner),
                 jnp.zeros((S, engine.h.num_options), bool), tick)


def test_fresh_learners_are_each_seeds_own_init_in_one_program():
    """Every seed's fresh learner is ``agent.init`` of its own key (bit for bit on one CPU),
    whatever seeds are initialised beside it."""
    engine, state = _engine(TrainConfig(num_envs=8, rollout_ticks=8, updates_per_chunk=1))
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    one = jax.jit(lambda k: engine.agent.init(k, engine.example_obs, engine.num_actions))
    for s in range(3):
        jax.tree.map(lambda a, b: np.testing.assert_array_equal(a[s], b),
                     state.learner, one(keys[s]))
    two = engine.init_learner(keys[1:])
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(a[1:], b), state.learner, two)


def test_a_chunk_seed_by_seed_trains_as_side_by_side_and_leaves_idle_seeds_alone():
    """On one CPU a chunk runs its seeds one after another: each seed learns what it learns
    side by side (to float tolerance), an idle seed keeps its state and counts nothing, and
    a seed's numbers do not depend on the seeds beside it."""
    engine, state = _engine(TrainConfig(num_envs=8, rollout_ticks=8, updates_per_chunk=1))
    active = [True, False, True]
    side, serial = (_chunk(engine, state, active, serial) for serial in (False, True))
    for out in (side, serial):
        new, stats = out[0], out[1]
        jax.tree.map(lambda a, b: np.testing.assert_array_equal(a[1], b[1]), new, state)
        jax.tree.map(lambda x: np.testing.assert_array_equal(x[1], 0), stats)
        assert (np.asarray(stats.learner_decisions)[[0, 2]] > 0).all()
        assert bool(out[5].all())
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5),
                 side[0].learner.params, serial[0].learner.params)
    # seed 2 alone, one after another: the same bits as beside seeds 0 and 1
    alone = _chunk(engine, jax.tree.map(lambda x: x[2:], state), [True], True)
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(a[0], b[2]),
                 (alone[0], alone[1]), (serial[0], serial[1]))


def test_a_few_due_seeds_of_many_run_as_a_smaller_batch_with_their_own_numbers():
    """Seeds side by side: a gate that concerns a few seeds of many runs them as a smaller
    batch (compiled ahead with the whole one), and each gives the numbers the whole batch
    gives it; more due seeds than the smaller batch holds run in the whole batch."""
    cfg = TrainConfig(num_envs=8, gate_envs=16, gate_max_ticks=60)
    engine, state = _engine(cfg)
    engine.episodes = seed_batched_episodes(engine.runner, engine.gamma, False)
    bank = engine.new_bank(state.learner)
    learned = jnp.zeros((3, engine.h.num_options), bool).at[:, 0].set(True)
    keys = jax.random.split(jax.random.PRNGKey(7), 3)
    results, calls = {}, {}
    for bucket in (3, 1):  # 3 seeds: a bucket of 3 never applies, one of 1 does
        engine.episode_calls = calls[bucket] = EpisodeCalls(engine.compile_episodes, True, bucket)
        ahead = CompileAhead(threads=1, enabled=True)
        engine.episodes_ahead(engine.gate_args(keys, state, bank, learned, [1] * 3, [0] * 3,
                                               [False] * 3, [0.8] * 3), cfg.gate_envs, ahead)
        assert len(calls[bucket].compiled) == (2 if bucket == 1 else 1)
        for due in ([False, True, False], [True, False, True]):
            results[bucket, tuple(due)], _ = engine.gate(
                keys, state, bank, learned, [1] * 3, [0] * 3, due, [0.8] * 3)
    # the calls found the programs compiled ahead under their own layouts: no other key
    assert len(calls[1].compiled) == 2 and len(calls[3].compiled) == 1
    small, whole = results[1, (False, True, False)], results[3, (False, True, False)]
    for name in whole:
        np.testing.assert_allclose(np.asarray(small[name])[1], np.asarray(whole[name])[1],
                                   rtol=1e-6)
    assert (np.asarray(small["env_steps"]) > 0).tolist() == [False, True, False]
    for name in whole:  # two due: the whole batch, the same program
        np.testing.assert_array_equal(results[1, (True, False, True)][name],
                                      results[3, (True, False, True)][name])


def test_evaluation_and_gate_share_one_compiled_program():
    cfg = TrainConfig(num_envs=8, gate_envs=16, eval_envs=16, gate_max_ticks=50, eval_max_ticks=50)
    engine, state = _engine(cfg)
    bank = engine.new_bank(state.learner)
    learned = jnp.zeros((3, engine.h.num_options), bool).at[:, 0].set(True)
    keys = jax.random.split(jax.random.PRNGKey(5), 3)
    _, first = engine.gate(keys, state, bank, learned, [1] * 3, [0] * 3, [True] * 3, [0.8] * 3)
    result, second = engine.evaluate(keys, bank, learned, state.learner)
    assert first > 0 and second == 0.0 and len(engine.episode_calls.compiled) == 1
    assert np.asarray(result["completed"]).shape == (3,)
    # evaluation needs no learner state: the same program and the same numbers without one
    alone, third = engine.evaluate(keys, bank, learned)
    assert third == 0.0 and len(engine.episode_calls.compiled) == 1
    jax.tree.map(np.testing.assert_array_equal, alone, result)


# the opt-out is a switch of ``enable_compilation_cache`` (what ``run`` calls first): one
# small program shows it as well as a whole run, without compiling a run's programs again
# (a repeated run's cache hits: tests/test_startup.py)
_ONE_PROGRAM = """
import collections, json
import jax, jax.numpy as jnp
from smjax.core.compile_cache import enable_compilation_cache
events = collections.Counter()
jax.monitoring.register_event_listener(lambda name, **kw: events.update([name.split("/")[-1]]))
enable_compilation_cache()
jax.jit(lambda x: jnp.cumsum(x * 2.0 + 1.0))(jnp.arange(5.0)).block_until_ready()
print(json.dumps({"hits": events["cache_hits"], "misses": events["cache_misses"]}))
"""


def _run_in_subprocess(env_vars: dict, code: str = _ONE_PROGRAM) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env.update(env_vars, PYTHONPATH=os.pathsep.join([str(ROOT / "tests"), str(ROOT)]))
    out = subprocess.run([sys.executable, "-c", code], env=env,
                         capture_output=True, text=True, check=True, timeout=600)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_compilation_cache_opt_out_neither_writes_nor_reads(tmp_path):
    # the same program is cached without it
    on, off = tmp_path / "on", tmp_path / "off"
    used = _run_in_subprocess({"SMJAX_CACHE_DIR": str(on)})
    assert used["misses"] > 0 and any(on.iterdir()), used
    unused = _run_in_subprocess({"SMJAX_CACHE_DIR": str(off), "SMJAX_COMPILATION_CACHE": "0"})
    assert not off.exists() and unused["hits"] == 0 and unused["misses"] == 0, unused


def _root_calls_give_key_where(key_cells: tuple[int, ...]):
    """KeyDoor with the root scripted: it calls give_key where the key lies in ``key_cells``,
    else walks right until the step cap (give_key is then never called in that episode)."""
    from smjax.options import declare

    env, params = make_keydoor()
    cells = jnp.asarray(key_cells)

    def root(key, state, params, mask):
        return jnp.where((state.key_pos == cells).any() & ~state.has_key, 0, 1)

    h = declare(env, "open_door", {"open_door": ["give_key", "right"], "give_key": ["primitives"]},
                policies={"open_door": root})
    cfg = TrainConfig(num_envs=8, gate_envs=64, gate_max_ticks=20)  # < the 30-step cap: one episode
    engine = Engine(env, params, h, make_agent("ppo", hidden_sizes=(16,)), cfg)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    state = SeedState(engine.reset(keys, jnp.zeros((2,), jnp.int32)), engine.init_learner(keys), keys)
    bank = engine.new_bank(state.learner)
    learned = jnp.zeros((2, h.num_options), bool)
    give_key = jnp.full((2,), h.option_index("give_key"), jnp.int32)
    # the gate's program, without its early stop (every environment plays to the end)
    args = (jax.random.split(jax.random.PRNGKey(4), 2), state.learner.params, bank, learned,
            give_key, jnp.zeros((2,), jnp.int32), jnp.asarray(True),
            engine._seed_temperatures("sample", 2), jnp.asarray(cfg.gate_max_ticks),
            jnp.zeros((2,), bool), early_stop_bounds([None] * 2))
    result, _ = engine.episode_calls(args, cfg.gate_envs)
    return {k: np.asarray(v) for k, v in result.items()}


def test_a_gate_leaves_out_environments_where_the_learner_is_never_called():
    # The key lies in cells 0-3, uniformly. Called in every environment: none left out.
    every = _root_calls_give_key_where((0, 1, 2, 3))
    np.testing.assert_array_equal(every["uncalled"], 0.0)
    # Called only where the key is in cell 0 or 1: about half the environments never call
    # the learner; they are neither successes nor failures of give_key.
    half = _root_calls_give_key_where((0, 1))
    assert ((half["uncalled"] > 0.3) & (half["uncalled"] < 0.7)).all(), half["uncalled"]
    assert (half["completed"] <= 1.0 - half["uncalled"] + 1e-6).all()
    # Never called: no evidence at all, reported as 0 (the level cannot pass on it).
    never = _root_calls_give_key_where(())
    np.testing.assert_array_equal(never["uncalled"], 1.0)
    np.testing.assert_array_equal(never["success"], 0.0)
    np.testing.assert_array_equal(never["completed"], 0.0)
