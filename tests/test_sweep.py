"""Hyper-parameter sweeps: every (point, seed) is a slot of one compiled program, and a
point's results are those of its run alone."""
import json

import jax
import numpy as np
import pytest

from _helpers import MachineLost, lose_machine_after_save
from hier_env import make_keydoor
from smjax.policy import load_policy
from smjax.train import ConfigError, TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.engine import Engine
from smjax.train.run import run
from smjax.train.seed_threads import group_size

CFG = dict(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=150,
           success_window=64, gate_envs=32, eval_envs=32, finetune="off", checkpoint_every=1e9)
LRS = [1e-4, 1e-3]
SWEEP = {"agent.learning_rate": LRS}


def _one_program(lowered: list, slots: int) -> bool:
    """One training chunk lowered, for a group of a sweep's slots (points x seeds): where
    the engine runs seeds in groups on threads, one program serves a group's size."""
    if len(lowered) != 1:
        return False
    size, threads = lowered[0]
    return size == group_size(threads, slots)


def _numbers(res: dict) -> dict:
    # seed_threads: how many groups ran (a sweep has more slots than its point alone)
    times = ("wall_seconds", "compile_seconds", "_raw", "seed_threads")
    return {k: v for k, v in res.items() if k not in times}


@pytest.fixture
def lowered(monkeypatch):
    """The seed-axis size of every training chunk program lowered (= compiled), with its
    engine's seed threads."""
    sizes = []
    init = Engine.__init__

    def counting_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        chunk, threads = self.chunk, self.seed_threads

        class Counting:
            def lower(_, state, *rest):
                sizes.append((state.key.shape[0], threads))
                return chunk.lower(state, *rest)

        self.chunk = Counting()

    monkeypatch.setattr(Engine, "__init__", counting_init)
    return sizes


def test_a_sweep_compiles_once_and_each_point_equals_its_run_alone(tmp_path, lowered):
    cfg = TrainConfig(**CFG)
    out = tmp_path / "sweep"
    swept = run(make_keydoor(), cfg, [0, 3], out, progress=False, sweep=SWEEP)
    assert _one_program(lowered, 4), lowered  # 2 points x 2 seeds, one training program
    assert [p["overrides"] for p in swept["points"]] == [{"agent.learning_rate": lr} for lr in LRS]
    on_disk = json.loads((out / "sweep.json").read_text())
    assert [p["overrides"] for p in on_disk["points"]] == [p["overrides"] for p in swept["points"]]
    assert on_disk["compile_seconds"] > 0
    for k in range(2):
        assert (out / f"point-{k}" / "results.json").is_file()
        assert (out / f"point-{k}" / "curves.csv").is_file()
    # a different learning rate trains different parameters
    banks = [p["results"]["_raw"]["bank"] for p in swept["points"]]
    differ = jax.tree.map(lambda a, b: not np.array_equal(a, b), banks[0], banks[1])
    assert any(jax.tree.leaves(differ))
    # the second point, run alone with the same seeds, gives the same numbers and curves
    alone = run(make_keydoor(), cfg.replace(agent={"learning_rate": LRS[1]}), [0, 3],
                tmp_path / "alone", progress=False)
    point = swept["points"][1]["results"]
    assert _numbers(point) == _numbers(alone)
    assert (out / "point-1" / "curves.csv").read_text() == (tmp_path / "alone" / "curves.csv").read_text()
    # each point saves its own policy, which repeats that point's final evaluation
    policy = load_policy(out / "point-1", env=make_keydoor())
    assert policy.evaluate()["success"] == point["final_success"] == alone["final_success"]


@pytest.mark.parametrize("sweep, needle", [
    ({"agent.hidden_sizes": [8]}, "sweepable: gamma, agent.learning_rate"),
    ({"num_envs": [8, 16]}, "cannot be swept"),
    ({"gamma": [0.9, 1.5]}, "'gamma' = 1.5: must be a number in"),
    ({"agent.nope": [1.0]}, "cannot be swept"),
    ({"agent.learning_rate": ["fast"]}, "must be a finite number"),
    ({"agent.learning_rate": [2.0]}, "learning_rate"),
    ({"agent.learning_rate": []}, "at least one value"),
])
def test_bad_sweeps_are_refused_before_training(tmp_path, sweep, needle, lowered):
    with pytest.raises(ConfigError, match=needle):
        run(make_keydoor(), TrainConfig(**CFG), [0], tmp_path / "bad", progress=False, sweep=sweep)
    assert lowered == [] and not (tmp_path / "bad" / "checkpoints").exists()


def test_a_gamma_sweep_point_equals_its_run_alone(tmp_path, lowered):
    cfg = TrainConfig(**(CFG | {"algo": "actor-critic"}))
    swept = run(make_keydoor(), cfg, [2], progress=False,
                sweep={"gamma": [0.9, 0.99], "agent.ent_coef": [0.01]})
    assert _one_program(lowered, 2), lowered
    alone = run(make_keydoor(), cfg.replace(gamma=0.9, agent={"ent_coef": 0.01}), [2],
                progress=False)
    assert swept["points"][0]["overrides"] == {"gamma": 0.9, "agent.ent_coef": 0.01}
    assert _numbers(swept["points"][0]["results"]) == _numbers(alone)
    assert _numbers(swept["points"][1]["results"]) != _numbers(alone)


def test_a_sweep_resumes_exactly_from_its_checkpoint(tmp_path, monkeypatch):
    cfg = TrainConfig(**CFG)
    straight = run(make_keydoor(), cfg, [0, 1], tmp_path / "straight", progress=False, sweep=SWEEP)
    # a slot has just finished its first level
    lose_machine_after_save(monkeypatch, lambda trainer: max(trainer.state.stage) == 1)
    out = tmp_path / "moved"
    with pytest.raises(MachineLost):
        run(make_keydoor(), cfg, [0, 1], out, progress=False, sweep=SWEEP)
    monkeypatch.undo()
    assert len(ckpt.load_meta(out)["meta"]["host"]["stage"]) == 4  # all slots checkpointed
    with pytest.raises(ConfigError, match="sweep"):  # another sweep cannot resume it
        run(make_keydoor(), cfg, [0, 1], out, progress=False, resume=True,
            sweep={"agent.learning_rate": [1e-4]})
    resumed = run(make_keydoor(), cfg, [0, 1], out, progress=False, resume=True, sweep=SWEEP)
    for a, b in zip(resumed["points"], straight["points"]):
        assert _numbers(a["results"]) == _numbers(b["results"])


@pytest.mark.parametrize("flag, message", [
    ("agent.hidden_sizes=8,16", "'agent.hidden_sizes' cannot be swept with algo 'ppo'; sweepable: "
                                "gamma, agent.learning_rate, agent.gae_lambda"),
    ("agent.learning_rate=1e-4,fast", "sweep agent.learning_rate must be a finite number"),
    ("agent.learning_rate=1e-4,3", "learning_rate must lie in (0.0, 1.0]"),
    ("agent.learning_rate", "--sweep must look like FIELD=V1,V2"),
])
def test_the_cli_refuses_bad_sweeps_in_one_line(flag, message, capsys, tmp_path):
    from smjax.cli import main

    argv = ["train", "craft/get_wood", "--quiet", "--sweep", flag, "--out", str(tmp_path / "r")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_help_explains_sweep(capsys):
    from smjax.cli import main

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "--sweep agent.learning_rate=1e-4,3e-4" in " ".join(capsys.readouterr().out.split())


def test_a_sweeps_files_count_as_a_run_and_overwrite_removes_them(tmp_path):
    from smjax.train.outdir import OutDirError, prepare_out_dir

    (tmp_path / "point-0").mkdir()
    (tmp_path / "point-0" / "results.json").write_text("{}")
    (tmp_path / "sweep.json").write_text("{}")
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(OutDirError, match="point-0"):
        prepare_out_dir(tmp_path, resume=False, overwrite=False)
    prepare_out_dir(tmp_path, resume=False, overwrite=True).release()
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["notes.txt"]
