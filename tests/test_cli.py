"""The command line: help, list, bench JSON line, a tiny train + resume + render + eval + plot,
errors."""
import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from smjax.cli import main
from smjax.core.timeline import TIMELINE


def test_help_lists_commands(capsys):
    assert main([]) == 0
    out = capsys.readouterr().out
    for cmd in ("train", "bench", "list", "plot", "eval", "render"):
        assert cmd in out
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "--resume" in capsys.readouterr().out


def test_list_shows_craft_tasks_and_hierarchies(capsys):
    assert main(["list", "craft/get_g", "--hierarchies"]) == 0
    out = capsys.readouterr().out
    assert "craft/get_gem" in out and "craft/get_gold" in out
    assert "[paper]" in out and "give_axe -> give_stick, give_iron" in out


def test_bench_prints_one_json_line():
    proc = subprocess.run([sys.executable, "-m", "smjax", "bench", "craft/get_wood", "--num-envs", "8",
                           "--steps", "5", "--repeats", "1"], capture_output=True, text=True,
                          env={"JAX_PLATFORMS": "cpu", "PATH": "/usr/bin:/bin"}, timeout=300)
    assert proc.returncode == 0, proc.stderr
    line = json.loads(proc.stdout.strip().splitlines()[-1])
    assert line["env"] == "craft/get_wood" and line["num_envs"] == 8 and line["steps"] == 5
    assert line["steps_per_second"] > 0 and line["compile_seconds"] > 0 and line["device"] == "cpu"


@pytest.mark.parametrize("argv, message", [
    (["train", "craft/get_diamond", "--quiet"], "unknown task 'craft/get_diamond'"),
    (["train", "craft/get_wood", "--set", "num_envs=0", "--quiet"], "'num_envs' = 0"),
    (["train", "craft/get_wood", "--set", "bogus=1", "--quiet"], "unknown config field"),
    (["train", "craft/get_wood", "--set", "num_env=3", "--quiet"], "Did you mean 'num_envs'?"),
    (["train", "craft/get_wood", "--env", "colour=red", "--quiet"], "unknown override"),
    (["bench", "nope/nothing"], "unknown task"),
    (["render", "craft/get_wood", "--policy", "/nonexistent/run"], "holds no saved policy"),
    (["eval", "/nonexistent/run"], "holds no saved policy"),
])
def test_bad_input_is_a_clear_error(argv, message, capsys, tmp_path):
    if argv[0] == "train":
        argv = argv + ["--out", str(tmp_path / "r")]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_train_resume_render_plot(tmp_path, capsys, monkeypatch):
    # the timeline is the process's: forget what other tests' runs in this process added
    monkeypatch.setattr(TIMELINE, "spans", {})
    monkeypatch.setattr(TIMELINE, "jax", {})
    out = tmp_path / "wood"
    args = ["train", "craft/get_wood", "--seeds", "1", "--num-envs", "16", "--max-episodes", "60",
            "--env", "observation=compact", "--set", "rollout_ticks=8", "--set", "eval_envs=8",
            "--finetune-episodes", "60", "--set", "success_window=60", "--set", "gate_envs=8",
            "--out", str(out), "--quiet"]
    assert main(args + ["--profile"]) == 0
    printed = capsys.readouterr()
    summary = json.loads(printed.out.splitlines()[0])
    assert summary["task"] == "get_wood" and summary["method"] == "top-down"
    results = json.loads((out / "results.json").read_text())
    assert results["config"]["num_envs"] == 16
    _check_profile(json.loads((out / "profile.json").read_text()), printed.err)
    # the same directory again without --resume is refused; --resume of a finished run is fine
    assert main(args) == 2
    assert "already holds" in capsys.readouterr().err
    assert main(["train", "craft/get_wood", "--resume", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["train", "craft/get_wood", "--resume", str(out), "--set", "gamma=0.5", "--quiet"]) == 2
    assert "gamma" in capsys.readouterr().err
    gif = tmp_path / "wood.gif"
    assert main(["render", "craft/get_wood", "--policy", str(out), "--out", str(gif), "--steps", "20"]) == 0
    with Image.open(gif) as im:
        assert im.n_frames >= 1 and im.size[0] > 100
        frame = im.convert("RGB")
        assert len(np.unique(np.asarray(frame).reshape(-1, 3), axis=0)) > 5  # not blank
    # the saved policy, evaluated on its own, repeats the run's final evaluation
    assert main(["eval", str(out)]) == 0
    evaluated = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert evaluated["success"] == results["final_success"]
    png = tmp_path / "overlay.png"
    assert main(["plot", str(out), str(out), "--out", str(png)]) == 0
    assert png.stat().st_size > 5000


def _check_profile(profile: dict, printed: str) -> None:
    """--profile: the command's phases in order, the compiling apart from the work it
    precedes, JAX's own stages inside them, and the same table on stderr."""
    spans = {s["label"]: s for s in profile["spans"]}
    for label in ("interpreter, imports and arguments", "environment, learner and hierarchy",
                  "training chunks", "compile: training chunks", "gates", "evaluation",
                  "checkpoint writes", "results.json, curves.csv, curves.png"):
        assert label in spans and spans[label]["seconds"] >= 0, label
        assert label in printed
    starts = [s["start"] for s in profile["spans"]]
    assert starts == sorted(starts) and starts[0] == 0.0
    # one program for every level, one for fine-tuning: never one per level
    assert spans["compile: training chunks"]["count"] <= 2
    # the phases never overlap: together they fit in the whole command
    assert sum(s["seconds"] for s in profile["spans"]) <= profile["total_seconds"] + 1e-6
    assert profile["jax"]["jax: tracing"]["count"] > 0


def test_a_users_own_task_is_listed_and_benched(capsys):
    # tests/user_tasks.py registers userkd/open_door when imported
    assert main(["list", "--import", "user_tasks", "userkd"]) == 0
    assert "userkd/open_door" in capsys.readouterr().out
    assert main(["bench", "user_tasks:userkd/open_door", "--num-envs", "2", "--steps", "2",
                 "--repeats", "1"]) == 0
    assert json.loads(capsys.readouterr().out)["env"] == "user_tasks:userkd/open_door"


@pytest.mark.slow
def test_a_users_own_task_trains_and_resumes_from_the_cli(tmp_path, capsys):
    out = tmp_path / "kd"
    args = ["train", "user_tasks:userkd/open_door", "--seeds", "1", "--num-envs", "8",
            "--max-episodes", "16", "--finetune", "off", "--set", "rollout_ticks=8",
            "--set", "eval_envs=8", "--set", "gate=false", "--set", "success_window=16",
            "--env", "max_steps=12", "--out", str(out), "--quiet"]
    assert main(args) == 0, capsys.readouterr().err
    summary = json.loads(capsys.readouterr().out.splitlines()[0])
    assert summary["task"] == "open_door"
    # resuming names the task the same way: the module is imported again from the name
    assert main(["train", "user_tasks:userkd/open_door", "--resume", str(out), "--quiet"]) == 0
    capsys.readouterr()


def test_an_unknown_user_module_is_a_clear_error(capsys):
    assert main(["bench", "no_such_module_here:a/b"]) == 2
    assert "cannot import 'no_such_module_here'" in capsys.readouterr().err
    assert main(["bench", "mine/open_chest"]) == 2
    assert "MODULE:ENV/TASK" in capsys.readouterr().err


def test_the_version_comes_from_package_metadata(monkeypatch):
    import importlib.metadata

    import smjax
    from smjax.core.version import smjax_version

    assert smjax.__version__ == importlib.metadata.version("smjax")

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr("smjax.core.version.version", missing)
    assert smjax_version() == "0+unknown"  # a bare source tree still writes results


def test_an_unknown_task_leaves_no_out_directory(tmp_path, capsys):
    out = tmp_path / "x2"
    assert main(["train", "craft/get_woodd", "--out", str(out), "--quiet"]) == 2
    assert "Did you mean 'craft/get_wood'" in capsys.readouterr().err
    assert not out.exists()


def test_render_help_describes_its_options(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "Write a GIF of one episode" in out
    for text in ("the GIF to write", "most environment steps", "frames per second"):
        assert text in out


def test_commands_work_when_a_folder_named_smjax_shadows_the_package(monkeypatch, capsys):
    """A clone folder ``smjax/`` beside a user's script becomes the (empty, namespace)
    package ``smjax`` while the installed modules still import under it (setuptools'
    editable finder): the CLI must not reach through the package's ``__init__``."""
    import types

    from smjax.core.version import shadowing_folder, warn_if_shadowed

    assert shadowing_folder() is None
    shadow = types.ModuleType("smjax")
    shadow.__path__ = ["/home/me/smjax"]  # a namespace package: no make, registry, __version__
    monkeypatch.setitem(sys.modules, "smjax", shadow)
    assert main(["list", "craft/get_w"]) == 0, capsys.readouterr().err
    assert "craft/get_wood" in capsys.readouterr().out
    with pytest.warns(UserWarning, match="the folder /home/me/smjax .* shadows the installed"):
        warn_if_shadowed()  # what importing smjax.core does: it is never silent
