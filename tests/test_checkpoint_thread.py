"""Checkpoints are written on a thread while training goes on: a failed write still stops
the run, a write holds the state of its save, the last one is on disk when the run returns,
and a save holds back only its own threads' stderr."""
import sys
import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hier_env import make_keydoor
from smjax.agents import make_agent
from smjax.train import checkpoint as ckpt
from smjax.train.checkpoint_orbax import quiet_orbax
from smjax.train.engine import Engine
from smjax.train.hooks import CheckpointHook, Hook
from smjax.train.loop import HierarchyTrainer
from smjax.train.plans import plan_levels
from test_hooks import SMALL


class Calls(Hook):
    def __init__(self):
        self.calls = []

    def chunk(self, trainer, report):
        self.calls.append("chunk")

    def end(self, trainer):
        self.calls.append("end")


def trainer_with(hooks, cfg):
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    return HierarchyTrainer(Engine(env, params, h, make_agent("ppo"), cfg),
                            plan_levels(h, "top-down"), [0, 1], hooks=hooks)


def test_a_failed_checkpoint_write_stops_the_run_at_the_next_chunk_and_keeps_the_last(
        tmp_path, monkeypatch):
    # checkpoints are written on a thread while training goes on: a write that fails still
    # stops the run, with its one-line error, and the checkpoint before it stays in force
    monkeypatch.setattr(CheckpointHook, "STAGE_GAP_WRITES", 0)  # every stage end writes
    real, steps = ckpt.save_checkpoint, []

    def second_write_fails(out_dir, step, arrays, meta):
        steps.append(step)
        if len(steps) == 2:
            raise ckpt.CheckpointError("disk full: the previous checkpoint is kept")
        return real(out_dir, step, arrays, meta)

    monkeypatch.setattr(ckpt, "save_checkpoint", second_write_fails)
    recorder = Calls()
    cfg = SMALL.replace(checkpoint_every=1e9)
    trainer = trainer_with([recorder, CheckpointHook(tmp_path, cfg, {})], cfg)
    with pytest.raises(ckpt.CheckpointError, match="disk full"):
        trainer.run()
    assert len(steps) == 2 and ckpt.load_meta(tmp_path)["step"] == steps[0]
    assert recorder.calls[-1] == "chunk"  # it never reached the end


def test_a_checkpoint_holds_the_host_state_of_its_save_not_of_its_write(tmp_path, monkeypatch):
    # the write runs on a thread while training changes the host state's lists: the step's
    # manifest and latest.json must both hold the state the save was made at


    class State:
        chunks, stage = 1, [0, 0]

        def to_json(self):
            return {"stage": self.stage}

    class Trainer:
        state, arrays = State(), {"a": jnp.zeros(3)}

        def training(self):
            return True

    go, written = threading.Event(), []
    monkeypatch.setattr(ckpt, "save_checkpoint",
                        lambda out, step, arrays, meta: (go.wait(10), written.append(meta)))
    hook, trainer = CheckpointHook(tmp_path, SMALL, {}), Trainer()
    hook.save(trainer)
    trainer.state.stage[0] = 1  # the next chunk moves a seed on
    go.set()
    hook.close()
    assert written[0]["host"]["stage"] == [0, 0]


def test_the_last_checkpoint_runs_beside_the_evaluation_and_its_failure_is_one_line(
        tmp_path, monkeypatch, capsys):
    real, steps = ckpt.save_checkpoint, []

    def record(out_dir, step, arrays, meta):
        steps.append(step)
        if meta["trained"] and "fail" in str(out_dir):
            raise ckpt.CheckpointError("disk full: the previous checkpoint is kept")
        return real(out_dir, step, arrays, meta)

    monkeypatch.setattr(ckpt, "save_checkpoint", record)
    cfg = SMALL.replace(checkpoint_every=1e9)
    raw = trainer_with([CheckpointHook(tmp_path / "ok", cfg, {})], cfg).run()
    # written by the time the run returns
    assert ckpt.load_meta(tmp_path / "ok")["meta"]["trained"] and len(steps) >= 2
    capsys.readouterr()
    again = trainer_with([CheckpointHook(tmp_path / "fail", cfg, {})], cfg).run()
    for a, b in zip(jax.tree.leaves(again["final"]), jax.tree.leaves(raw["final"])):
        np.testing.assert_array_equal(a, b)  # the results stand
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "last checkpoint was not written (disk full" in err
    assert not ckpt.load_meta(tmp_path / "fail")["meta"]["trained"]  # the one before it


def test_a_checkpoint_holds_back_its_own_threads_stderr_only(capsys):
    """While a save runs on its thread, training's stderr (a warning, the progress bar)
    passes straight through; the save's own is held, then passed on, or dropped if the
    save failed."""
    import threading


    for failed in (False, True):
        inside, release = threading.Event(), threading.Event()

        def save():
            with quiet_orbax() as quiet:
                print("the save's", file=sys.stderr)
                inside.set()
                release.wait(10)
                quiet["failed"] = failed

        thread = threading.Thread(target=save)
        thread.start()
        inside.wait(10)
        print("training's", file=sys.stderr)
        assert capsys.readouterr().err == "training's\n"
        release.set()
        thread.join(10)
        assert capsys.readouterr().err == ("" if failed else "the save's\n")
