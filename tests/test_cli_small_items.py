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
