"""Exits that were ``internal error`` or silent: each is one clear line with exit 2, given
before anything compiles (out of memory, bad numbers, damaged files, unused overrides)."""
from __future__ import annotations

import os
import time

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import pytest

from smjax.cli import main
from smjax.cli_errors import user_message
from smjax.train import memory


def _cli(argv, capsys, limit: float = 15) -> tuple[int, str]:
    t0 = time.perf_counter()
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    assert time.perf_counter() - t0 < limit  # refused before any compile
    return code, err


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
    code, err = _cli(_train(tmp_path, "--num-envs", "8", *sets), capsys)
    assert code == 2 and "batch too large" in err and f"lower {setting}" in err, err
    assert len(err.strip().splitlines()) == 1
