"""The output directory under attack: ``--overwrite`` deletes only what the refusal named,
nothing is written or deleted through a planted symbolic link, and an empty ``--out``
is refused instead of falling back to a default directory."""
from __future__ import annotations

import os
import time

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import pytest

from _helpers import cli_answer
from smjax.train.outdir import LOCK_NAME, OutDirError, RunExistsError, prepare_out_dir


def test_overwrite_deletes_only_what_the_refusal_named(tmp_path):
    out = tmp_path / "d"
    (out / "checkpoints").mkdir(parents=True)
    (out / "checkpoints" / "model.pt").write_text("w")  # another tool's file
    (out / "results.json").write_text("{}")
    with pytest.raises(RunExistsError) as refused:
        prepare_out_dir(out, resume=False, overwrite=False)
    assert "results.json" in str(refused.value) and "checkpoints" not in str(refused.value)
    prepare_out_dir(out, resume=False, overwrite=True).release()
    assert not (out / "results.json").exists()
    assert (out / "checkpoints" / "model.pt").read_text() == "w"


def test_overwrite_keeps_other_files_inside_a_checkpoints_folder(tmp_path):
    out = tmp_path / "d"
    (out / "checkpoints" / "step-3").mkdir(parents=True)
    (out / "checkpoints" / "latest.json").write_text("{}")
    (out / "checkpoints" / "notes.txt").write_text("mine")
    prepare_out_dir(out, resume=False, overwrite=True).release()
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["notes.txt"]


def test_a_planted_lock_link_is_never_written_through(tmp_path):
    precious = tmp_path / "precious.txt"
    precious.write_text("precious")
    out = tmp_path / "r"
    out.mkdir()
    (out / LOCK_NAME).symlink_to(precious)
    with pytest.raises(OutDirError, match="symbolic link"):
        prepare_out_dir(out, resume=False, overwrite=False)
    assert precious.read_text() == "precious"
    assert (out / LOCK_NAME).is_symlink()  # not deleted either


@pytest.mark.parametrize("name", ["checkpoints", "tensorboard", "results.json", "curves.csv",
                                  "point-0"])
def test_run_files_that_are_links_are_refused_and_never_followed(tmp_path, name):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.txt").write_text("keep")
    out = tmp_path / "r"
    out.mkdir()
    (out / "results.json").write_text("{}") if name != "results.json" else None
    (out / name).symlink_to(elsewhere)
    for overwrite in (False, True):
        with pytest.raises(OutDirError, match="symbolic link"):
            prepare_out_dir(out, resume=False, overwrite=overwrite)
    assert (elsewhere / "keep.txt").read_text() == "keep"
    assert not (out / LOCK_NAME).exists()  # the lock is released on refusal


def test_a_link_inside_checkpoints_is_refused(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "r"
    (out / "checkpoints").mkdir(parents=True)
    (out / "checkpoints" / "step-1").symlink_to(elsewhere)
    with pytest.raises(OutDirError, match="step-1 is a symbolic link"):
        prepare_out_dir(out, resume=False, overwrite=True)
    assert elsewhere.is_dir()


def test_the_lock_is_not_taken_over_when_it_is_a_fifo(tmp_path):
    out = tmp_path / "r"
    out.mkdir()
    os.mkfifo(out / LOCK_NAME)
    t0 = time.perf_counter()
    with pytest.raises(OutDirError, match="not a regular file"):
        prepare_out_dir(out, resume=False, overwrite=False)
    assert time.perf_counter() - t0 < 5


def test_an_empty_out_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", ""], capsys)
    assert code == 2 and "--out is empty" in err
    assert not (tmp_path / "runs").exists()
    with pytest.raises(OutDirError, match="empty"):
        prepare_out_dir("", resume=False, overwrite=False)


def test_an_overlong_out_name_is_one_line(tmp_path, capsys):
    code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(tmp_path / ("x" * 300))],
                     capsys)
    assert code == 2 and "is 300 bytes long" in err and "at most 255 bytes" in err, err
    assert len(err.strip().splitlines()) == 1 and len(err) < 300


def test_overwrite_with_a_checkpoints_link_is_one_clear_line(tmp_path, capsys):
    out = tmp_path / "r"
    out.mkdir()
    (out / "curves.csv").write_text("x")
    (out / "checkpoints").symlink_to(tmp_path)
    code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(out), "--overwrite"],
                     capsys)
    assert code == 2 and "symbolic link" in err
    assert (out / "curves.csv").exists()  # refused before anything was deleted
