"""Helpers shared by several test files: losing the machine after a checkpoint (the resume
tests: test_resume, test_sweep, test_finetune, ...), loading a script of benchmarks/, and
a CLI answer that compiled nothing."""
import importlib.util
from pathlib import Path

import jax

from smjax.train.hooks import CheckpointHook

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_benchmark(name: str):
    """The module of ``benchmarks/NAME.py`` (benchmarks/ is not a package)."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class MachineLost(Exception):
    """The machine went away right after a checkpoint (raised by ``lose_machine_after_save``)."""


def lose_machine_after_save(monkeypatch, when) -> None:
    """Make every checkpoint save raise ``MachineLost`` once written, if ``when(trainer)``."""
    save = CheckpointHook.save

    def save_then_lose_the_machine(hook, trainer):
        save(hook, trainer)
        if when(trainer):
            raise MachineLost

    monkeypatch.setattr(CheckpointHook, "save", save_then_lose_the_machine)


# the keep-the-better counters that checkpoint format 4 added to the host state
KEEP_BETTER_KEYS = ("check_success", "kept", "baseline")


def _stored(out) -> tuple[dict, dict, int]:
    """The checkpoint in ``out``: its metadata, its leaves by position ("0", "1", ...) and
    their number."""
    import orbax.checkpoint as ocp

    from smjax.train import checkpoint as ckpt

    info = ckpt.load_meta(out)
    leaves = ocp.StandardCheckpointer().restore(ckpt.checkpoint_dir(out) / info["path"])
    return info, leaves, max(int(k) for k in leaves) + 1


def _rewrite(out, info: dict, arrays: list, fmt: int | None = None) -> None:
    """Save ``arrays`` with ``info``'s metadata over the checkpoint in ``out``, as format
    ``fmt`` (None: the format it had), without the keep-the-better counters."""
    from smjax.train import checkpoint as ckpt

    for key in KEEP_BETTER_KEYS:
        info["meta"]["host"]["finetune"].pop(key)
    meta = info["meta"] if fmt is None else info["meta"] | {"format": fmt}
    ckpt.save_checkpoint(out, info["step"], arrays, meta)


def without_levels_bank(out) -> None:
    """Drop the keep-the-better counters from the checkpoint in ``out`` (its arrays stay):
    its seeds resume as from format 3 or older, a seed already fine-tuning without its
    levels' bank."""
    info, leaves, n = _stored(out)
    _rewrite(out, info, [leaves[str(i)] for i in range(n)])


def as_format_3(out, bank_leaves: int) -> None:
    """Rewrite the checkpoint in ``out`` as smjax wrote it before it kept the levels' bank
    for fine-tuning (checkpoint format 3): that bank's ``bank_leaves`` leaves, the last
    ones, dropped."""
    info, leaves, n = _stored(out)
    _rewrite(out, info, [leaves[str(i)] for i in range(n - bank_leaves)], fmt=3)


def as_format_2(out, window: int) -> None:
    """Rewrite the format-3 checkpoint in ``out`` (``as_format_3``) as smjax wrote it before
    the running-success windows were arrays (format 2): the window arrays (the last leaves) dropped,
    each window as the host list of ``[total, count]`` batches that format kept (oldest
    first, trimmed to the most recent batches holding ``window`` episodes)."""
    import numpy as np

    from smjax.train import checkpoint as ckpt

    info, leaves, n = _stored(out)
    # TrainArrays' last fields: window (total, count, next), task_window (total, count, next)
    windows = [np.asarray(leaves[str(i)]) for i in range(n - 6, n)]

    def lists(total, count, nxt):
        out = []
        for t, c, k in zip(total, count, nxt):
            batches, seen = [], 0
            for j in range(len(c)):  # newest first, until the window is covered
                i = (k - 1 - j) % len(c)
                if c[i] == 0 or seen >= window:
                    break
                batches.insert(0, [float(t[i]), int(c[i])])
                seen += int(c[i])
            out.append(batches)
        return out

    host = info["meta"]["host"]
    host["history"] = lists(*windows[:3])
    host["finetune"]["task_history"] = lists(*windows[3:])
    arrays = [leaves[str(i)] if str(i) in leaves else np.zeros((0,)) for i in range(n - 6)]
    ckpt.save_checkpoint(out, info["step"], arrays, info["meta"] | {"format": 2})


_COMPILES = [0]


def _count_compiles(event: str, *_args, **_kwargs) -> None:
    if event == "/jax/core/compile/backend_compile_duration":
        _COMPILES[0] += 1


jax.monitoring.register_event_duration_secs_listener(_count_compiles)


def cli_answer(argv, capsys, *, compiles: bool = False) -> tuple[int, str]:
    """``smjax ARGV``'s exit code and stderr, which holds no traceback and no internal
    error; unless ``compiles``, nothing was compiled on the way (a refusal comes before
    any program is built, whatever the machine's speed)."""
    from smjax.cli import main

    before = _COMPILES[0]
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    assert compiles or _COMPILES[0] == before, f"compiled before answering: {err}"
    return code, err
