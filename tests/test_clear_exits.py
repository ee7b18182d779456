"""Exits that were ``internal error`` or silent: each is one clear line with exit 2, given
before anything compiles (out of memory, bad numbers, damaged files, unused overrides)."""
from __future__ import annotations

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import pytest

from _helpers import cli_answer
from smjax.cli import main
from smjax.cli_errors import user_message
from smjax.train import memory


def _train(tmp_path, *extra) -> list[str]:
    return ["train", "craft/make_stick", "--quiet", "--out", str(tmp_path / "r"), *extra]


@pytest.mark.parametrize("text", [
    "INTERNAL: Failed to execute XLA Runtime executable: run time error: Out of memory "
    "allocating 36000000000 bytes.",
    "INTERNAL: Failed to allocate buffer for Literal",
    "RESOURCE_EXHAUSTED: Out of memory while trying to allocate 8.00GiB"])
def test_xla_cpu_out_of_memory_is_a_user_error(text):
    message = user_message(jax.errors.JaxRuntimeError(text), "1 seed(s) x num_envs 8")
    assert message is not None and message.startswith("out of memory with 1 seed(s) x num_envs 8")


@pytest.mark.parametrize("sets, setting", [
    (["--set", "reset_pool=1048576"], "reset_pool"),
    (["--set", "success_window=1000000", "--set", "updates_per_chunk=65536",
      "--max-episodes", "1000000"], "success_window")])
def test_the_memory_estimate_counts_the_pool_and_the_windows(tmp_path, capsys, monkeypatch,
                                                             sets, setting):
    monkeypatch.setattr(memory, "available_bytes", lambda: 2 * 2**30)
    code, err = cli_answer(_train(tmp_path, "--num-envs", "8", *sets), capsys)
    assert code == 2 and "batch too large" in err and f"lower {setting}" in err, err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("argv, needle", [
    (["train", "craft/make_stick", "--coordinator-timeout", "inf"], "--coordinator-timeout"),
    (["train", "craft/make_stick", "--coordinator-timeout", "nan"], "--coordinator-timeout"),
    (["bench", "craft/make_stick", "--steps", "3000000000"], "bench steps"),
    (["bench", "craft/make_stick", "--repeats", "0"], "bench repeats")])
def test_numbers_past_their_range_are_usage_errors(tmp_path, capsys, argv, needle):
    code, err = cli_answer(argv + (["--out", str(tmp_path / "r")] if argv[0] == "train" else []), capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err


CURVES = "seed,level,template,episodes,env_steps,avg_return\n0,1,root,10,80,0.5\n"


@pytest.mark.parametrize("results, field", [
    ("[1, 2, 3]", "not a smjax results file"), ('{"finetune": [1]}', "'finetune'"),
    ('{"final_success": "high"}', "'final_success'"), ('{"method": 7}', "'method'"),
    ('{"finetune": {"final_success_before": [true]}}', "'finetune.final_success_before'")])
def test_plot_refuses_a_damaged_results_json(tmp_path, capsys, results, field):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "curves.csv").write_text(CURVES)
    (tmp_path / "run" / "results.json").write_text(results)
    code, err = cli_answer(["plot", str(tmp_path / "run"), "--out", str(tmp_path / "p.png")], capsys)
    assert code == 2 and "results.json" in err and field in err, err
    assert not (tmp_path / "p.png").exists()


def _good_meta() -> dict:
    host = {"stage": [0], "started": [False], "levels": [], "curves": [], "finetune": {},
            "compile_seconds": 0.0, "wall_seconds": 0.0, "chunks": 0}
    run = {"task": "craft/make_stick", "seeds": [0], "env_overrides": {}}
    return {"run": run, "host": host, "settings": {}, "format": 5}


@pytest.mark.parametrize("damage, field", [
    (lambda m: m["run"].__setitem__("seeds", "x"), "run.seeds"),
    (lambda m: m["run"].__setitem__("seeds", [True]), "run.seeds"),
    (lambda m: m["run"].pop("seeds"), "run.seeds"),
    (lambda m: m["run"].__setitem__("env_overrides", []), "run.env_overrides"),
    (lambda m: m["host"].__setitem__("curves", "x"), "host.curves"),
    (lambda m: m["host"].__setitem__("curves", [1, 2]), "host.curves"),
    (lambda m: m.__setitem__("settings", 5), "settings")])
def test_a_damaged_but_valid_json_checkpoint_index_is_refused(tmp_path, capsys, damage, field):
    """latest.json and the step's manifest agree (a damage written with them), so only the
    fields' types show it."""
    import numpy as np

    from smjax.train import checkpoint as ckpt

    meta = _good_meta()
    damage(meta)
    ckpt.save_checkpoint(tmp_path / "r", 1, {"a": np.zeros(3, np.float32)}, meta)
    code, err = cli_answer(["train", "craft/make_stick", "--quiet", "--resume", str(tmp_path / "r")],
                     capsys)
    assert code == 2 and ckpt.LATEST in err and f"field {field!r}" in err, err
    assert len(err.strip().splitlines()) == 1


def test_a_map_seed_without_a_fixed_map_is_refused(tmp_path, capsys):
    """Every episode draws its own map unless the map is fixed: the seed would be ignored."""
    import smjax

    code, err = cli_answer(_train(tmp_path, "--env", "map_seed=3"), capsys)
    assert code == 2 and "map_seed=3" in err and "add --fixed-map" in err, err
    with pytest.raises(ValueError, match="add --fixed-map"):
        smjax.make("craft/get_gem", map_seed=3)
    a, _ = smjax.make("craft/get_gem", fixed_map=True, map_seed=3)  # with the flag: accepted
    assert a is not None


@pytest.mark.parametrize("argv", [["train"], ["train", "craft/make_stick", "--seeds", "x"],
                                  ["nosuch"], ["bench"], ["train", "craft/make_stick", "--bogus"]])
def test_argparse_errors_are_two_lines(capsys, argv):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 2, err
    assert "error:" in err[0] and err[1].endswith("--help`)")


def test_an_out_of_memory_message_names_the_sizes_that_were_set():
    from smjax.cli_train import batch_description
    from smjax.train import TrainConfig

    cfg = TrainConfig(num_envs=8, reset_pool=500_000, agent={"hidden_sizes": [4096, 4096]})
    batch = batch_description(cfg, 2)
    assert batch == "2 seed(s) x num_envs 8, reset_pool 500000, hidden_sizes '[4096, 4096]'"
    oom = jax.errors.JaxRuntimeError("INTERNAL: Out of memory allocating 36000000000 bytes.")
    assert user_message(oom, batch).endswith("; lower one of these")
    assert batch_description(TrainConfig(num_envs=8), 1) == "1 seed(s) x num_envs 8"
