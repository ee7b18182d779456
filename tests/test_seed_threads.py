"""Seeds in groups on threads (a CPU): the same numbers as one program over every seed."""
import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hier_env import make_keydoor

from smjax.train import TrainConfig
from smjax.train.chunks import ChunkRunner
from smjax.train.run import run
from smjax.train.seed_threads import Busy, SeedGroups, group_count, thread_count

CFG = TrainConfig(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=1500,
                  success_window=64, gate_envs=32, eval_envs=32, finetune="on",
                  finetune_max_episodes=96)


def test_a_run_in_seed_groups_equals_one_program_over_every_seed(monkeypatch):
    calls, joint_threads = [], []
    grouped_run, joint_chunk = SeedGroups.run, ChunkRunner.joint

    def counted(self, compiled, args):
        calls.append(self.groups)
        return grouped_run(self, compiled, args)

    def joint_on(self, *args):
        joint_threads.append(threading.current_thread().name)
        return joint_chunk(self, *args)

    monkeypatch.setattr(SeedGroups, "run", counted)
    monkeypatch.setattr(ChunkRunner, "joint", joint_on)
    monkeypatch.setenv("SMJAX_SEED_THREADS", "1")
    one = run(make_keydoor(), CFG, [0, 1, 2], progress=False)
    assert calls == [] and joint_threads and all(
        n == threading.main_thread().name for n in joint_threads)
    joint_threads.clear()
    # three seeds in two groups: the second padded with a copy of the last seed
    monkeypatch.setenv("SMJAX_SEED_THREADS", "2")
    grouped = run(make_keydoor(), CFG, [0, 1, 2], progress=False)
    assert calls and set(calls) == {2}
    # a chunk with seeds at a level and seeds in joint fine-tuning ran its programs at once
    assert any(n.startswith("smjax-joint-chunk") for n in joint_threads)
    assert one["finetune"]["episodes"][0] > 0  # the joint chunk ran too
    times = ("wall_seconds", "compile_seconds", "_raw", "seed_threads")
    assert {k: v for k, v in grouped.items() if k not in times} == {
        k: v for k, v in one.items() if k not in times}
    assert (one["seed_threads"], grouped["seed_threads"]) == (1, 2)


def test_an_environments_weakly_typed_state_is_made_strong_where_episodes_start():
    # KeyDoor's step counter is ``jnp.asarray(0)``, weakly typed. A seed group's rows and a
    # checkpoint's arrays come back from the host strongly typed, so the run's state is made
    # strong where episodes start: its chunk runs in seed groups, and a resumed run calls
    # the programs compiled for the run before it
    from smjax.agents import make_agent
    from smjax.train.engine import Engine

    env, params = make_keydoor()
    _, state = jax.eval_shape(env.reset_env, jax.random.PRNGKey(0), params)
    assert state.t.weak_type
    engine = Engine(env, params, env.hierarchies()["paper"], make_agent("ppo"), CFG)
    carry = engine.reset(jax.random.split(jax.random.PRNGKey(0), 2), np.zeros((2,), np.int32))
    assert not [x for x in jax.tree.leaves(carry) if x.weak_type]
    assert SeedGroups.for_program(2, (carry,)) is not None


def _per_seed_program(x, shared, y):
    return {"sum": x * 2 + shared, "rows": y.sum(axis=1)}


@pytest.mark.parametrize("seeds, groups", [(4, 2), (5, 2), (5, 3), (2, 2)])
def test_groups_split_and_join_every_seed_in_place(seeds, groups):
    x = jnp.arange(seeds, dtype=jnp.float32)
    y = jnp.arange(seeds * 3, dtype=jnp.int32).reshape(seeds, 3)
    shared = jnp.float32(10.0)
    args = (x, shared, y)
    axes = (0, None, 0)
    g = SeedGroups.for_program(groups, args, axes)
    assert g is not None and g.groups == groups
    shapes = g.shapes(args)
    assert shapes[0].shape == (g.size,) and shapes[1] is shared and shapes[2].shape == (g.size, 3)
    compiled = jax.jit(_per_seed_program).lower(*shapes).compile()
    out = g.program(compiled)(*args)
    want = _per_seed_program(*args)
    for k in want:
        np.testing.assert_array_equal(np.asarray(out[k]), np.asarray(want[k]))
        assert out[k].shape[0] == seeds


def test_one_thread_or_one_seed_runs_one_program():
    args = (jnp.zeros((3, 2)),)
    assert SeedGroups.for_program(1, args) is None
    assert SeedGroups.for_program(4, (jnp.zeros((1, 2)),)) is None
    assert SeedGroups.for_program(4, args).groups == 3  # never more groups than seeds
    # no group of copies alone: 10 seeds on 8 threads are 5 groups of 2
    ten = SeedGroups.for_program(8, (jnp.zeros((10, 2)),))
    assert (ten.groups, ten.size) == (5, 2)


def test_the_thread_setting_is_checked(monkeypatch):
    assert thread_count(False) == 1  # seeds side by side: nothing to split
    monkeypatch.setenv("SMJAX_SEED_THREADS", "3")
    assert thread_count(True) == 3
    for bad in ("two", "0", "-1"):
        monkeypatch.setenv("SMJAX_SEED_THREADS", bad)
        with pytest.raises(ValueError, match="SMJAX_SEED_THREADS"):
            thread_count(True)


def test_a_group_of_skipped_seeds_alone_does_not_run():
    x = jnp.arange(4, dtype=jnp.float32)
    skip = jnp.asarray([True, True, False, True])
    args = (x, skip)
    g = SeedGroups.for_program(2, args, (0, 0), busy=Busy(1, False, droppable=True))
    compiled = jax.jit(lambda v, s: {"twice": v * 2}).lower(*g.shapes(args)).compile()
    calls = []

    def counted(*a):
        calls.append(a)
        return compiled(*a)

    out = g.program(counted)(*args)
    assert len(calls) == 1  # only the group holding seed 2
    assert float(out["twice"][2]) == 4.0  # the others' results are meaningless
    out = g.program(counted)(x, jnp.ones(4, bool))  # none due: one group runs, for the shapes
    assert len(calls) == 2 and out["twice"].shape == (4,)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=2, max_size=11), st.integers(2, 5))
def test_busy_seeds_are_dealt_evenly_and_every_seed_comes_back_in_place(busy, threads):
    seeds = len(busy)
    args = (np.arange(seeds, dtype=np.float32), np.asarray(busy))
    g = SeedGroups(seeds, group_count(threads, seeds), (0, 0), Busy(1, True, droppable=False))
    rows, has_busy = g.deal(args)
    assert all(len(r) == g.size for r in rows)
    assert sorted(set(np.concatenate(rows).tolist())) == list(range(seeds))
    counts = [int(np.asarray(busy)[r].sum()) for r in rows]
    # padding copies a busy seed only where every seed is busy (each group is then full)
    assert max(counts) - min(counts) <= 1
    assert sum(counts) == sum(busy) + (g.groups * g.size - seeds if all(busy) else 0)
    assert has_busy == [c > 0 for c in counts]
    # every group runs (an idle seed's results are its state), and each comes back in place
    out = g.program(lambda x, b: {"x": x + 1, "b": b})(*args)
    np.testing.assert_array_equal(np.asarray(out["x"]), args[0] + 1)
    np.testing.assert_array_equal(np.asarray(out["b"]), args[1])


def test_a_call_on_the_last_calls_arrays_takes_their_groups_and_a_donated_one_is_copied(
        monkeypatch):
    seeds = 5
    x = jnp.arange(seeds, dtype=jnp.float32)
    bank = jnp.arange(seeds * 2, dtype=jnp.float32).reshape(seeds, 2)
    g = SeedGroups.for_program(2, (x, bank))
    # the state is donated, as a chunk's is; the bank only read
    compiled = jax.jit(lambda v, b: {"x": v + b.sum(1)}, donate_argnums=(0,)).lower(
        *g.shapes((x, bank))).compile()
    program = g.program(compiled)
    reused = []
    reuse = SeedGroups._reuse

    def spied(self, whole, key):
        parts = reuse(self, whole, key)
        reused.append(parts is not None)
        return parts

    monkeypatch.setattr(SeedGroups, "_reuse", spied)
    first = program(x, bank)
    assert reused == [False, False]
    second = program(first["x"], bank)  # the result joined last call, the bank it read
    assert reused[2:] == [True, True]
    np.testing.assert_array_equal(np.asarray(second["x"]), np.asarray(x + 2 * bank.sum(1)))
    # first["x"]'s groups' arrays went into the second call and were donated there:
    # a call on it again copies its rows anew, with the same numbers
    again = program(first["x"], bank)
    assert reused[4:] == [False, True]
    np.testing.assert_array_equal(np.asarray(again["x"]), np.asarray(second["x"]))
    # the same arrays dealt otherwise (another busy set) are copied too
    other = SeedGroups(seeds, 2, busy=Busy(1, True, droppable=False))
    flags = jnp.asarray([True, False, False, False, True])
    kept = jax.jit(lambda v, b: {"v": v + 1, "b": b}).lower(*other.shapes((x, flags))).compile()
    out = other.program(kept)(x, flags)
    out = other.program(kept)(out["v"], jnp.asarray([False, True, True, False, False]))
    assert reused[-2:] == [False, False]
    np.testing.assert_array_equal(np.asarray(out["v"]), np.asarray(x + 2))
