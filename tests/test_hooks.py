"""The driver loop's side jobs are hooks: a run with its own hooks gets every chunk's report
and its results (a sweep: each point's), and a run without hooks writes and prints nothing."""
from hier_env import make_keydoor
from smjax.agents import make_agent
from smjax.train import TrainConfig
from smjax.train.engine import Engine
from smjax.train.hooks import Hook, import_ahead
from smjax.train.loop import HierarchyTrainer
from smjax.train.plans import plan_levels

SMALL = TrainConfig(num_envs=8, rollout_ticks=8, updates_per_chunk=2, success_window=32,
                    gate_envs=16, eval_envs=16, max_episodes_per_level=150,
                    finetune_mode="turns", finetune_max_episodes=160, finetune_turn_episodes=80,
                    finetune_threshold=1.0)


class Recorder(Hook):
    def __init__(self):
        self.calls, self.reports, self.outcomes = [], [], []

    def start(self, trainer):
        self.calls.append("start")

    def chunk(self, trainer, report):
        self.calls.append("chunk")
        self.reports.append(report)

    def end(self, trainer):
        self.calls.append("end")

    def results(self, trainer, report):
        self.calls.append("results")
        # the run's files as this hook finds them: the built-in hooks run first
        found = sorted(p.name for p in report.out_dir.iterdir()) if report.out_dir else []
        self.outcomes.append((report, found))


def _trainer(hooks, seeds=(0, 1), cfg=SMALL):
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    return HierarchyTrainer(Engine(env, params, h, make_agent("ppo"), cfg),
                            plan_levels(h, "top-down"), list(seeds), hooks=hooks)


def test_a_hook_gets_every_chunks_report_and_nothing_is_printed(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    recorder = Recorder()
    trainer = _trainer([recorder])
    raw = trainer.run()
    assert recorder.calls[0] == "start" and recorder.calls[-1] == "end"
    reports = recorder.reports
    assert [r.chunk for r in reports] == list(range(1, trainer.state.chunks + 1))
    # every (seed, stage) pair ends once: two levels and fine-tuning for two seeds
    assert reports[-1].stages_done == 6 and reports[-1].seeds == []
    assert sum(r.stage_ended for r in reports) >= 3
    names = {s.name for r in reports for s in r.scalars}
    assert any(n.endswith("/running_success") for n in names)
    assert any(n.endswith("/gate_success") for n in names)
    assert "seed_1/finetune/task_success" in names
    assert {s.where for r in reports for s in r.seeds} >= {"L1", "L2", "FT"}
    assert raw["finetune"]["episodes"][0] > 0
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    assert list(tmp_path.iterdir()) == []


def _writes(tmp_path, monkeypatch, gap_writes: float) -> tuple[list, int]:
    """The chunks the checkpoint hook wrote at (stage ends only: no periodic writes), and
    how many chunks ended a stage."""
    from smjax.train.hooks import CheckpointHook

    monkeypatch.setattr(CheckpointHook, "STAGE_GAP_WRITES", gap_writes)
    written = []
    save = CheckpointHook.save
    monkeypatch.setattr(CheckpointHook, "save", lambda hook, trainer: (
        written.append(trainer.state.chunks), save(hook, trainer)))
    recorder = Recorder()
    cfg = SMALL.replace(checkpoint_every=1e9)
    _trainer([recorder, CheckpointHook(tmp_path, cfg, {})], cfg=cfg).run()
    return written, sum(r.stage_ended for r in recorder.reports)


def test_stage_end_checkpoints_are_coalesced_but_the_first_and_last_are_written(
        tmp_path, monkeypatch):
    # no gap: a write at every chunk that ended a stage
    every, ends = _writes(tmp_path / "every", monkeypatch, 0)
    assert len(every) == ends >= 3
    # a gap longer than the run: the first stage end and the last are written, nothing between
    few, _ = _writes(tmp_path / "few", monkeypatch, 1e9)
    assert few == [every[0], every[-1]]


class _FakeWandbRun:
    def __init__(self, **kwargs):
        self.kwargs, self.rows, self.axes, self.summary = kwargs, [], {}, {}
        self.finished, self.exit_code = False, None

    def define_metric(self, name, step_metric):
        self.axes[name] = step_metric

    def log(self, row):
        self.rows.append(dict(row))

    def finish(self, exit_code=None):
        self.finished, self.exit_code = True, exit_code


def _fake_wandb(monkeypatch) -> list:
    """A stand-in wandb module (W&B's client is an optional extra); the runs it started."""
    import sys
    import types

    runs = []
    fake = types.SimpleNamespace(init=lambda **kw: runs.append(_FakeWandbRun(**kw)) or runs[-1])
    monkeypatch.setitem(sys.modules, "wandb", fake)
    return runs


def test_a_callers_hooks_run_beside_the_built_in_ones_and_wandb_gets_every_scalar(
        tmp_path, monkeypatch):
    # a stand-in wandb module records what the hook hands it (the real one, offline, in
    # the test below where it is installed)
    import numpy as np

    from smjax.train.run import run
    from smjax.train.wandb_hook import WandbHook

    runs = _fake_wandb(monkeypatch)
    recorder = Recorder()
    cfg = SMALL.replace(checkpoint_every=1e9)
    raw = run(make_keydoor(), cfg, [0], tmp_path / "out", progress=False,
              hooks=[recorder, WandbHook(project="p", mode="offline")])
    assert recorder.calls[0] == "start" and recorder.calls[-2:] == ["end", "results"]
    assert (tmp_path / "out" / "checkpoints").is_dir()  # the built-in hooks ran too
    # the results, once, with the run's directory, written there before this hook ran
    ((report, found),) = recorder.outcomes
    assert report.out_dir == tmp_path / "out" and report.overrides is None
    assert report.results == {k: v for k, v in raw.items() if k != "_raw"}
    assert report.raw is raw["_raw"]
    assert {"results.json", "curves.csv", "policy", "checkpoints"} <= set(found)
    (wb,) = runs
    assert wb.finished and wb.kwargs["project"] == "p" and wb.kwargs["mode"] == "offline"
    assert wb.kwargs["config"] == {k: raw["config"][k] for k in wb.kwargs["config"]}
    # every scalar of every chunk, charted against its own env step, then the chunk's row
    expected = []
    for report in recorder.reports:
        expected += [{s.name: s.value, f"{s.name}/env_step": s.step} for s in report.scalars]
        expected.append({"chunk": report.chunk})
    assert [{k: v for k, v in row.items() if k != "env_steps_per_second"}
            for row in wb.rows] == expected
    assert all(wb.axes[name] == f"{name}/env_step" for name in wb.axes) and wb.axes
    # the results, evaluated after training ended, are the run's summary before it finishes
    assert wb.exit_code is None
    for key in ("final_success", "episodes_to_threshold", "total_episodes", "wall_seconds",
                "compile_seconds", "seeds", "device"):
        assert wb.summary[key] == raw[key]
    assert wb.summary["final_success_mean"] == np.mean(raw["final_success"])
    assert wb.summary["finetune/episodes"] == raw["finetune"]["episodes"]
    assert "config" not in wb.summary and "levels" not in wb.summary


def test_wandb_hook_finishes_a_trainer_run_on_its_own_and_a_failed_run_as_failed(monkeypatch):
    import types

    from smjax.train.wandb_hook import WandbHook

    runs = _fake_wandb(monkeypatch)
    # outside run() no results follow training: the W&B run finishes with it
    _trainer([WandbHook()], seeds=(0,)).run()
    assert runs[0].finished and runs[0].summary == {}
    # a run that failed before its results is finished, failed, when the hook starts again
    hook, trainer = WandbHook(), types.SimpleNamespace(cfg=SMALL)
    hook.start(trainer)
    hook.start(trainer)
    assert runs[1].finished and runs[1].exit_code == 1 and not runs[2].finished


def test_wandb_hook_writes_an_offline_run_whose_summary_holds_the_results(tmp_path,
                                                                          monkeypatch):
    import json

    import pytest

    wandb = pytest.importorskip("wandb")
    from smjax.train.run import run
    from smjax.train.wandb_hook import WandbHook

    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    summaries = []  # each run's summary as it finishes (an offline run's is read back empty)

    def init(**kwargs):
        started = wandb_init(**kwargs)
        finish = started.finish
        started.finish = lambda **kw: (summaries.append(dict(started.summary)), finish(**kw))
        return started

    wandb_init = wandb.init
    monkeypatch.setattr(wandb, "init", init)
    cfg = SMALL.replace(checkpoint_every=1e9)
    run(make_keydoor(), cfg, [0, 1], tmp_path / "out", progress=False,
        hooks=[WandbHook(project="smjax-test", dir=str(tmp_path))])
    assert list(tmp_path.rglob("*.wandb"))
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    (summary,) = summaries
    assert summary["final_success"] == results["final_success"]
    assert summary["final_success_mean"] == pytest.approx(sum(results["final_success"]) / 2)
    assert summary["wall_seconds"] == results["wall_seconds"]


def test_wandb_hook_without_wandb_says_how_to_install_it(monkeypatch):
    import sys

    import pytest

    from smjax.train.wandb_hook import WandbHook

    monkeypatch.setitem(sys.modules, "wandb", None)  # import wandb raises ImportError
    with pytest.raises(ImportError, match=r"pip install 'smjax\[wandb\]'"):
        WandbHook()


def test_a_callers_hook_gets_each_sweep_points_results_with_its_directory(tmp_path,
                                                                          monkeypatch):
    from smjax.train.run import run
    from smjax.train.wandb_hook import WandbHook

    runs = _fake_wandb(monkeypatch)
    recorder = Recorder()
    cfg = SMALL.replace(finetune="off", max_episodes_per_level=60, checkpoint_every=1e9)
    lrs = [1e-4, 1e-3]
    out = tmp_path / "sweep"
    swept = run(make_keydoor(), cfg, [0], out, progress=False,
                sweep={"agent.learning_rate": lrs}, hooks=[recorder, WandbHook()])
    assert recorder.calls[-3:] == ["end", "results", "results"]
    # one W&B run for the sweep, finished after the last point, each point's results in
    # its summary under the point's overrides
    (wb,) = runs
    assert wb.finished
    for lr, point in zip(lrs, swept["points"]):
        assert (wb.summary[f"agent.learning_rate={lr}/final_success"]
                == point["results"]["final_success"])
    assert [r.out_dir for r, _ in recorder.outcomes] == [out / "point-0", out / "point-1"]
    assert [r.overrides for r, _ in recorder.outcomes] == [{"agent.learning_rate": lr}
                                                          for lr in lrs]
    for (report, found), point in zip(recorder.outcomes, swept["points"]):
        assert report.results == {k: v for k, v in point["results"].items() if k != "_raw"}
        assert report.raw is point["results"]["_raw"]
        assert found == ["curves.csv", "policy", "results.json"]
    # no output directory: the hooks still get every point's results, with none
    recorder = Recorder()
    run(make_keydoor(), cfg, [0], progress=False, sweep={"agent.learning_rate": lrs},
        hooks=[recorder])
    assert [(r.out_dir, f) for r, f in recorder.outcomes] == [(None, [])] * 2


def test_a_hooks_modules_are_imported_on_a_thread_and_a_failing_one_waits_for_its_use():
    import sys

    class Later(Hook):
        modules = ("this_module_does_not_exist", "colorsys")

    sys.modules.pop("colorsys", None)
    thread = import_ahead([Hook(), Later()])
    assert thread is not None and thread.name == "smjax-import-ahead"
    thread.join(timeout=60)
    # the missing module raised nowhere; the one after it was still imported
    assert not thread.is_alive() and "colorsys" in sys.modules
    assert import_ahead([Hook()]) is None  # no modules named: no thread


def test_hooks_hear_of_the_run_while_it_is_built_and_are_closed_if_building_fails(monkeypatch):
    class Building(Hook):
        def __init__(self):
            self.calls = []

        def prepare(self, trainer):  # the run's shape is known, nothing is built yet
            self.calls.append(("prepare", len(trainer.seeds), trainer.num_stages))

        def close(self):
            self.calls.append("close")

    hook = Building()

    def refused(self, ahead):
        raise MemoryError("no room for the first state")

    monkeypatch.setattr(HierarchyTrainer, "_build_state", refused)
    try:
        _trainer([hook])
        raise AssertionError("the trainer was built")
    except MemoryError:
        pass
    assert hook.calls == [("prepare", 2, 3), "close"]
