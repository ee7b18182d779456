"""Small CLI items: an unknown ``list`` prefix, ``plot --out`` a directory, and ``render``
checking its arguments before it plays (which may take minutes)."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import pytest

from _helpers import cli_answer


def test_list_with_an_unknown_prefix_is_an_error(capsys):
    code, err = cli_answer(["list", "nosuch"], capsys)
    assert code == 2 and "no registered task starts with 'nosuch'" in err


def test_plot_refuses_an_existing_directory_as_out(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "curves.csv").write_text("seed,level,template,episodes,env_steps,running_success\n"
                                    "0,1,a,10,100,0.5\n0,1,a,20,200,0.6\n")
    code, err = cli_answer(["plot", str(run), "--out", str(tmp_path)], capsys)
    assert code == 2 and "directory" in err


@pytest.mark.parametrize("extra, needle", [
    (["--steps", str(10**9)], "--steps"), (["--fps", "1e-6"], "--fps"),
    (["--out", "."], "directory"), (["--out", "/no/such/folder/x.gif"], "does not exist"),
    (["--out", "x" * 252 + ".gif"], "at most 255 bytes"),
])
def test_render_checks_its_arguments_before_playing(tmp_path, capsys, monkeypatch, extra, needle):
    import smjax.viz.play as play

    def never(*a, **k):
        raise AssertionError("played before checking its arguments")

    monkeypatch.setattr(play, "random_frames", never)
    monkeypatch.chdir(tmp_path)
    code, err = cli_answer(["render", "craft/make_stick", *extra], capsys)
    assert code == 2 and needle in err, err


def test_the_readable_summary_gives_each_seed_or_many_seeds_mean_and_range():
    from smjax.cli_train import readable_summary

    results = {"env": "craft", "task": "make_stick", "method": "top-down", "algo": "ppo",
               "seeds": [0, 1], "final_success": [0.9383, 0.9305], "eval_policy": "sample",
               "episodes_to_threshold": [3351, 3297], "finetune": {"episodes": [1261, 1561]},
               "wall_seconds": 25.87, "compile_seconds": 1.49, "success_unbounded": False}
    text = readable_summary(results, "runs/quickstart")
    assert text.splitlines()[0] == "craft/make_stick, top-down ppo, 2 seeds:"
    assert "0.938  0.930 (mean 0.934;" in text and "episodes     3,351  3,297 (until" in text
    assert "episodes 1,261  1,561" in text and "1.5 s of it compiling" in text
    assert "runs/quickstart" in text
    many = dict(results, seeds=list(range(10)), final_success=[0.8 + i / 100 for i in range(10)],
                episodes_to_threshold=[5000 + 100 * i for i in range(10)], finetune=None,
                success_unbounded=True)
    text = readable_summary(many, "runs/x")
    assert "final return         mean 0.845, lowest 0.800, highest 0.890 (the" in text
    assert "mean 5,450, lowest 5,000, highest 5,900" in text and "fine-tuning" not in text
    short = dict(results, episodes_to_threshold=[3351, None])  # a level's budget ran out
    assert "3,351  not reached (until" in readable_summary(short, "runs/x")
    many["episodes_to_threshold"] = [None] + many["episodes_to_threshold"][1:]
    assert "highest 5,900, 1 not reached (until" in readable_summary(many, "runs/x")
