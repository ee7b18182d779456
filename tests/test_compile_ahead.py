"""Programs compiled ahead on a thread (``smjax.train.ahead``): the same programs, so the same
numbers; a compile for other arguments, or one that failed, is done again where needed."""
import threading
import time
from concurrent.futures import Future

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hier_env import make_keydoor
from smjax.core.timeline import TIMELINE
from smjax.train import TrainConfig
from smjax.train.ahead import CompileAhead, Pending, abstract, resolve, signature
from smjax.train import engine as engine_module
from smjax.train.run import run
from test_finetune import SMALL, _strip_timing

JOINT_SMALL = SMALL | {"finetune_mode": "joint"}


def _ahead_labels() -> dict:
    # a compile an earlier run left under way (its run ended without needing it) counts
    # when it ends: wait for it, so it is not taken for one of the run under test
    for thread in threading.enumerate():
        if thread.name == "smjax-compile-ahead":
            thread.join()
    return {k: v[1] for k, v in TIMELINE.jax.items() if k.startswith("compile ahead")}


_WHERE_NEEDED: dict = {}


def _run_compiled_where_needed(cfg: TrainConfig) -> dict:
    """The run with nothing compiled ahead (``SMJAX_COMPILE_AHEAD=0``), once per process:
    the same for every way of compiling ahead compared with it."""
    if "run" not in _WHERE_NEEDED:
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("SMJAX_COMPILE_AHEAD", "0")
            before = _ahead_labels()
            _WHERE_NEEDED["run"] = run(make_keydoor(), cfg, [0], progress=False)
            assert _ahead_labels() == before  # off: nothing compiled on a thread
    return _WHERE_NEEDED["run"]


@pytest.mark.parametrize("threads,from_start", [(1, False), (1, True), (3, True)],
                         ids=["where-first-run", "cpu", "accelerator"])
def test_a_run_compiled_ahead_gives_the_numbers_of_one_compiled_where_needed(
        monkeypatch, threads, from_start):
    # each backend's way (``CompileAhead.for_backend``: a CPU's one thread, an
    # accelerator's three), and the level chunk compiled where first run: from the start,
    # it compiles from the trainer's construction, for shapes traced before its state exists
    monkeypatch.setattr(CompileAhead, "for_backend",
                        classmethod(lambda cls: cls(threads, from_start=from_start)))
    cfg = TrainConfig(**JOINT_SMALL)
    where_needed = _run_compiled_where_needed(cfg)
    before = _ahead_labels()
    compiles = []
    real = engine_module.compile_program

    def counted(jitted, args, name, *rest):
        compiles.append(name)
        return real(jitted, args, name, *rest)

    monkeypatch.setattr(engine_module, "compile_program", counted)
    ahead = run(make_keydoor(), cfg, [0], progress=False)
    compiled = _ahead_labels()
    # the gate's (and evaluation's) episodes program, joint fine-tuning's chunk and, from
    # the start, the level chunk
    # (counted since ``before``: other tests in this process may have compiled ahead too)
    assert {k: d for k, n in compiled.items() if (d := n - before.get(k, 0))} == {
        "compile ahead (a thread): episodes-16": 1, "compile ahead (a thread): joint_chunk": 1
    } | ({"compile ahead (a thread): level_chunk": 1} if from_start else {})
    # each compiled once: the arguments compiled for are those the run calls them with
    assert sorted(compiles) == ["chunk", "episodes-16", "joint_chunk"]
    assert _strip_timing(ahead) == _strip_timing(where_needed)


def _program(x):
    return x * 2


def test_a_compile_ahead_for_other_arguments_is_not_used():
    jitted = jax.jit(_program)
    ahead = CompileAhead(threads=1, enabled=True)
    pending = ahead.submit("x", lambda xs: jitted.lower(*xs).compile(),
                           (jnp.zeros((3,), jnp.float32),))
    args = (jnp.ones((4,), jnp.float32),)  # another shape: compiled here
    program, seconds = resolve(pending, args, lambda xs: jitted.lower(*xs).compile())
    np.testing.assert_array_equal(program(*args), np.full((4,), 2.0))
    assert seconds > 0
    # a compiled program is returned as it is, at no cost
    assert resolve(program, args, None) == (program, 0.0)
    ahead.close()


def test_a_failed_compile_ahead_is_compiled_again_and_raises_where_used():
    failed: Future = Future()
    failed.set_exception(RuntimeError("lost"))
    args = (jnp.zeros((2,)),)
    entry = Pending(failed, signature(args))
    program, _ = resolve(entry, args, lambda xs: jax.jit(_program).lower(*xs).compile())
    np.testing.assert_array_equal(program(*args), np.zeros(2))

    def broken(xs):
        raise ValueError("the real error")
    with pytest.raises(ValueError, match="the real error"):
        resolve(entry, args, broken)


def test_closing_cancels_what_has_not_started_and_off_submits_nothing(monkeypatch):
    ahead = CompileAhead(threads=1, enabled=True)
    gate: Future = Future()
    first = ahead.submit("slow", lambda xs: gate.result(), (jnp.zeros(()),))
    while not first.future.running():
        time.sleep(0.01)
    second = ahead.submit("queued", lambda xs: 1, (jnp.zeros(()),))
    ahead.close()
    gate.set_result("done")
    assert first.future.result(timeout=10) == "done"
    assert second.future.cancelled()
    assert ahead.submit("after", lambda xs: 1, ()) is None
    monkeypatch.setenv("SMJAX_COMPILE_AHEAD", "0")
    assert not CompileAhead().on


def test_abstract_arguments_keep_shape_dtype_layout_and_weak_type():
    args = ({"a": jnp.ones((2, 3), jnp.int32)}, jnp.asarray(1.0), 7)
    shapes = abstract(args)
    assert signature(shapes) == signature(args)
    assert shapes[1].weak_type and shapes[2] == 7


def test_ctrl_c_while_waiting_for_a_compile_ahead_ends_the_run():
    interrupted: Future = Future()
    interrupted.set_exception(KeyboardInterrupt())
    args = (jnp.zeros((2,)),)
    with pytest.raises(KeyboardInterrupt):
        resolve(Pending(interrupted, signature(args)), args, lambda xs: pytest.fail("compiled"))


@pytest.mark.parametrize("mode", ["joint", "turns"])
def test_a_rehearsed_level_change_and_stage_start_change_no_seed(mode):
    # on a CPU, the programs of a level change and of fine-tuning's start compile before the
    # compiles ahead begin, by running them with every seed's mask off
    from smjax.agents import make_agent
    from smjax.train.engine import Engine
    from smjax.train.loop import HierarchyTrainer
    from smjax.train.plans import plan_levels

    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    cfg = TrainConfig(**(SMALL | {"finetune_mode": mode}))
    trainer = HierarchyTrainer(Engine(env, params, h, make_agent("ppo"), cfg),
                               plan_levels(h, "top-down"), [0, 1], hooks=[])
    before = jax.tree.map(np.asarray, trainer.arrays)
    host = trainer.state.to_json()
    trainer.rehearse_changes()
    after = jax.tree.map(np.asarray, trainer.arrays)
    assert jax.tree.structure(before) == jax.tree.structure(after)
    for b, a in zip(jax.tree.leaves(before), jax.tree.leaves(after)):
        np.testing.assert_array_equal(a, b)
    assert trainer.state.to_json() == host


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="a CPU's choice")
def test_a_cpu_compiles_ahead_from_the_start_on_one_thread():
    # one thread beside the main thread's small programs (a second makes a run slower)
    ahead = CompileAhead.for_backend()
    assert (ahead.threads, ahead.from_start) == (1, True)


@pytest.mark.parametrize("threads,beside", [(1, False), (3, True)], ids=["one", "three"])
def test_where_the_level_chunk_compiles_on_the_main_thread_one_thread_waits_for_it(
        monkeypatch, threads, beside):
    # a trainer whose level chunk is not compiled ahead (built without an ahead, as on a
    # mesh) compiles it where it first runs: an ahead of one thread queues the rest after
    # that compile, with the level change rehearsed first; one with threads to spare
    # compiles them beside it
    from smjax.agents import make_agent
    from smjax.train.engine import Engine
    from smjax.train.loop import HierarchyTrainer
    from smjax.train.plans import plan_levels

    monkeypatch.setattr(CompileAhead, "for_backend",
                        classmethod(lambda cls: cls(threads, enabled=True, from_start=True)))
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    cfg = TrainConfig(**JOINT_SMALL)
    trainer = HierarchyTrainer(Engine(env, params, h, make_agent("ppo"), cfg),
                               plan_levels(h, "top-down"), [0], hooks=[])
    assert trainer.runner.level_program is None  # nothing submitted at construction
    seen, rehearsed, real_run = {}, [], trainer.runner.run

    def level_chunk(*args, **kwargs):
        seen["rest submitted first"] = trainer.ahead_rest
        return real_run(*args, **kwargs)

    monkeypatch.setattr(trainer.runner, "run", level_chunk)
    monkeypatch.setattr(trainer, "rehearse_changes", lambda: rehearsed.append(True))
    trainer.start([0])
    trainer.chunk([0], trainer.controls())
    trainer.ahead.close()
    assert seen == {"rest submitted first": beside}
    assert trainer.ahead_rest and bool(rehearsed) is not beside
