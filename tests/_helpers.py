"""Helpers shared by several test files: losing the machine after a checkpoint (the resume
tests: test_resume, test_sweep, test_finetune, ...), a checkpoint marked as of another
format, loading a script of benchmarks/, and a CLI answer that compiled nothing."""
import importlib.util
import time
from pathlib import Path

import jax

from smjax.train.ahead import compiling
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


def with_format(out, version) -> None:
    """Mark the latest checkpoint in ``out`` as of checkpoint format ``version`` (None: no
    format recorded), in ``latest.json`` and its step's manifest alike, as another smjax
    would have written it."""
    import json

    from smjax.train import checkpoint as ckpt
    from smjax.train.manifest import MANIFEST

    root = ckpt.checkpoint_dir(out)
    index = json.loads((root / ckpt.LATEST).read_text())
    manifest = json.loads((root / index["path"] / MANIFEST).read_text())
    for meta in (index["meta"], manifest["meta"]):
        meta.pop("format", None)
        if version is not None:
            meta["format"] = version
    (root / ckpt.LATEST).write_text(json.dumps(index))
    (root / index["path"] / MANIFEST).write_text(json.dumps(manifest))


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

    # a compile ahead that an earlier test's run left under way (a run that ends early does
    # not wait for it) would land in this count
    deadline = time.monotonic() + 300
    while compiling() and time.monotonic() < deadline:
        time.sleep(0.05)
    before = _COMPILES[0]
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    assert compiles or _COMPILES[0] == before, f"compiled before answering: {err}"
    return code, err


def pending_rows(seed: int, num_options: int, num_envs: int, features: int, actions: int,
                 idle: int):
    """Every option's pending rows ``[O, B]`` of a joint batch: decisions still running
    (random), none for option ``idle``."""
    import jax.numpy as jnp

    from smjax.core.transition import no_pending

    k = jax.random.split(jax.random.PRNGKey(seed + 100), 3)
    shape = (num_options, num_envs)
    rows = jax.tree.map(lambda x: jnp.repeat(x[None], num_options, 0),
                        no_pending(jnp.zeros((num_envs, features)), actions))
    return rows._replace(
        obs=jax.random.normal(k[0], shape + (features,)),
        decision=jax.random.bernoulli(k[1], 0.5, shape).at[idle].set(False),
        reward=jax.random.uniform(k[2], shape), discount=jnp.full(shape, 0.9, jnp.float32))


def assert_trees_close(a, b, **tol) -> None:
    """Every leaf of ``a`` close to the same leaf of ``b`` (same structure)."""
    import numpy as np

    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), **tol)


def joint_record(seed: int, dims: tuple, decide, reward_scale: float = 1.0,
                 done_rate: float = 0.15):
    """A random joint record ``[T, B, O]`` (observations shared) of ``dims = (T, B, O, A,
    F)``; ``decide(key)`` draws the bool ``[T, B, O]`` decisions."""
    import jax.numpy as jnp

    from smjax.core.transition import Transition

    T, B, O, A, F = dims
    k = jax.random.split(jax.random.PRNGKey(seed), 8)
    return Transition(
        obs=jax.random.normal(k[0], (T, B, F)),
        action=jax.random.randint(k[1], (T, B, O), 0, A),
        action_mask=jax.random.bernoulli(k[6], 0.8, (T, B, O, A)).at[..., 0].set(True),
        log_prob=-jax.random.uniform(k[7], (T, B, O), minval=0.5, maxval=2.0),
        value=jax.random.normal(k[2], (T, B, O)), decision=decide(k[3]),
        reward=jax.random.uniform(k[4], (T, B, O)) * reward_scale,
        discount=jnp.full((T, B, O), 0.97, jnp.float32),
        done=jax.random.bernoulli(k[5], done_rate, (T, B, O)))

