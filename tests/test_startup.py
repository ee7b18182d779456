"""Start-up: a run imports only what it uses (plotting, TensorBoard and MuJoCo cost
seconds of import before anything trains), the timeline that ``--profile`` prints, and
the program cache (its keys, its entries written atomically)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from smjax.core.timeline import Timeline

ROOT = Path(__file__).resolve().parents[1]

_CRAFT_RUN = """
import json, sys
from smjax.train import TrainConfig
from smjax.train.run import run
cfg = TrainConfig(num_envs=8, rollout_ticks=4, max_episodes_per_level=8, success_window=4,
                  gate=False, eval_envs=8, eval_max_ticks=20, finetune="off")
run("craft/get_wood", cfg, [0], progress=False)
heavy = ("matplotlib", "tensorboardX", "mujoco", "brax", "tqdm", "PIL")
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in heavy)))
"""


def test_a_craft_run_imports_no_plotting_tensorboard_or_mujoco():
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", _CRAFT_RUN], env=env, capture_output=True,
                         text=True, check=True, timeout=600)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_the_timeline_sums_repeated_spans_and_orders_them_by_start():
    t = Timeline(start=0.0)
    t.add("b", 5.0, 1.0)
    t.add("a", 1.0, 2.0)
    t.add("b", 9.0, 0.5)
    d = t.to_dict()
    assert [s["label"] for s in d["spans"]] == ["a", "b"]
    assert d["spans"][1] == {"label": "b", "start": 5.0, "seconds": 1.5, "count": 2}
    with t.span("c"):
        pass
    assert t.spans["c"][2] == 1 and t.spans["c"][1] >= 0
    assert "a" in t.report() and "whole command" in t.report()


def test_the_timeline_starts_at_the_process_start():
    # the interpreter ran before this module was imported: the clock started earlier
    assert Timeline().now() > 0.0


_EXIT_HANDLER = """
import atexit, os, pathlib
atexit.register(lambda: pathlib.Path(os.environ["SMJAX_TEST_MARKER"]).write_text("ran"))
"""


@pytest.mark.parametrize("argv, code", [(["list"], 0), (["train", "craft/no_such_task"], 2)])
def test_the_command_ends_with_its_exit_handlers_run_and_its_output_whole(tmp_path, argv, code):
    # the command skips the interpreter's teardown (os._exit), not what an exit runs
    (tmp_path / "exit_handler_module.py").write_text(_EXIT_HANDLER)
    marker = tmp_path / "marker"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(tmp_path)]),
               JAX_PLATFORMS="cpu", SMJAX_TEST_MARKER=str(marker))
    out = subprocess.run([sys.executable, "-m", "smjax", *argv, "--import", "exit_handler_module"],
                         env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == code, out.stderr
    assert marker.read_text() == "ran"
    if code == 0:  # a piped stdout is block-buffered: all of it was flushed
        assert "craft/get_gem" in out.stdout and out.stdout.endswith("\n")
    else:
        assert "no_such_task" in out.stderr


def _train(out: Path, cache: Path, *extra: str) -> dict:
    """A tiny registered-task run in its own process; its results and profile."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu", SMJAX_CACHE_DIR=str(cache))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    cmd = [sys.executable, "-m", "smjax", "train", "craft/get_wood", "--seeds", "1",
           "--num-envs", "8", "--max-episodes", "16", "--set", "rollout_ticks=4",
           "--set", "success_window=8", "--set", "eval_envs=8", "--set", "gate_envs=8",
           "--finetune-episodes", "16", "--quiet", "--profile", "--overwrite", "--out", str(out),
           *extra]
    subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, timeout=600)
    results = json.loads((out / "results.json").read_text())
    jax_counts = json.loads((out / "profile.json").read_text())["jax"]

    def count(name: str) -> int:
        return jax_counts.get(name, {"count": 0})["count"]

    return {"final": results["final_success"], "levels": results["levels"],
            "loaded": count("programs loaded as StableHLO (no tracing)"),
            "hits": count("persistent-cache hits"), "misses": count("persistent-cache misses")}


def test_a_repeated_run_loads_its_programs_untraced_and_a_changed_one_does_not(tmp_path):
    cache = tmp_path / "cache"
    first = _train(tmp_path / "a", cache)
    assert first["loaded"] == 0 and first["misses"] > 0
    # a run is a few dozen programs: host-side plumbing (banks, stacking, example
    # observations) is not run op by op, which compiled one tiny program per primitive
    assert first["misses"] <= 60, first
    saved = sorted((cache / "smjax-programs").iterdir())
    # the level chunk, the fine-tuning chunk, the episodes program, the learners' init and
    # the environments' reset
    assert len(saved) >= 5
    second = _train(tmp_path / "a", cache)
    assert second["loaded"] == len(saved)
    # every program the first run compiled is loaded from JAX's cache, none compiled again
    assert second["misses"] == 0 and second["hits"] >= first["misses"], (first, second)
    assert second["final"] == first["final"] and second["levels"] == first["levels"]
    # another config is traced, never a saved program loaded; another evaluation batch is
    # another episodes program, compiled anew (a traced value such as gamma changes no
    # program, only the config's key: test_a_program_key_changes_with_everything_...)
    other = _train(tmp_path / "b", cache, "--set", "eval_envs=16")
    assert other["loaded"] == 0 and other["misses"] > 0, other


def test_a_damaged_saved_program_is_dropped_and_traced_again(tmp_path, monkeypatch):
    """Every saved program a run loads goes through ``compile_program``: a damaged entry
    (garbage, or a write cut off) is dropped, the program traced and saved again, and it
    gives the same numbers."""
    import jax
    import jax.numpy as jnp

    from smjax.train import program_cache as pc

    monkeypatch.setattr(pc, "_directory", lambda: tmp_path / "smjax-programs")
    saved = []  # a program is saved where it was traced (exported), never where loaded
    save = pc._save
    monkeypatch.setattr(pc, "_save", lambda *a: (saved.append(a[0]), save(*a)))
    jitted = jax.jit(lambda x, y: {"sum": x + y["b"], "scaled": 2.0 * x})
    args = (jnp.arange(3.0), {"b": jnp.ones(3)})
    expected = {"sum": np.arange(3.0) + 1.0, "scaled": 2.0 * np.arange(3.0)}
    identity = {"task": "craft/get_wood", "gamma": 0.9}

    def compiled_and_run():
        out = pc.compile_program(jitted, args, "chunk", identity)(*args)
        assert jax.tree.all(jax.tree.map(np.array_equal, out, expected))

    compiled_and_run()
    [entry] = (tmp_path / "smjax-programs").iterdir()
    assert saved == [entry]
    compiled_and_run()  # loaded, not traced
    assert saved == [entry]
    for damage in (b"not a program", entry.read_bytes()[:40]):  # garbage, a cut-off write
        entry.write_bytes(damage)
        saved.clear()
        compiled_and_run()
        assert saved == [entry] and pc._load(entry) is not None  # traced, saved anew whole


def test_a_program_key_changes_with_everything_the_program_depends_on(monkeypatch):
    import jax.numpy as jnp

    from smjax.train import program_cache as pc

    args = (jnp.zeros((2, 3)), {"b": jnp.zeros(4, jnp.int32)})
    base = pc.program_key({"gamma": 0.9}, "chunk", args)
    assert pc.program_key({"gamma": 0.9}, "chunk", args) == base
    assert pc.program_key({"gamma": 0.99}, "chunk", args) != base
    assert pc.program_key({"gamma": 0.9}, "joint_chunk", args) != base
    assert pc.program_key({"gamma": 0.9}, "chunk", (jnp.zeros((3, 3)), args[1])) != base
    assert pc.program_key({"gamma": 0.9}, "chunk", (args[0], {"b": jnp.zeros(4)})) != base
    monkeypatch.setattr(pc, "source_digest", lambda: "other smjax source")
    assert pc.program_key({"gamma": 0.9}, "chunk", args) != base
    monkeypatch.undo()
    platform = pc._platform()
    monkeypatch.setattr(pc, "_platform", lambda: platform | {"jax": "0.0.0"})
    assert pc.program_key({"gamma": 0.9}, "chunk", args) != base


def test_only_runs_named_by_smjax_code_are_cached():
    from smjax.train import program_cache as pc

    identity = {"task": "craft/get_wood", "seeds": [0, 1], "gamma": 0.9}
    named = pc.cacheable_identity("craft/get_wood", None, identity)
    assert named == {"task": "craft/get_wood", "gamma": 0.9}  # seeds are inputs, not program
    assert pc.cacheable_identity(("env", "params"), None, identity) is None
    assert pc.cacheable_identity("craft/get_wood", object(), identity) is None


def test_a_failed_atomic_write_leaves_neither_file_nor_temporary(tmp_path, monkeypatch):
    """results.json and the program cache's entries share one writer: a failed write
    leaves no temporary file behind (the cache's is best effort: no error either)."""
    from smjax.train import program_cache as pc
    from smjax.core.files import FILE_MODE, atomic_write_bytes, atomic_write_text

    atomic_write_text(tmp_path / "a.json", "{\"é\": 1}\n")
    assert json.loads((tmp_path / "a.json").read_text(encoding="utf-8")) == {"é": 1}
    atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01", durable=False)
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "b.bin").stat().st_mode & 0o777 == FILE_MODE

    class Exported:
        def serialize(self):
            return b"program"

    def no_rename(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", no_rename)
    pc._save(tmp_path / "cache" / "p.bin", Exported(), None)  # best effort: no error
    with pytest.raises(OSError):
        atomic_write_text(tmp_path / "c.json", "{}")
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["a.json", "b.bin"]
    pc._save(tmp_path / "cache" / "p.bin", Exported(), None)
    assert (tmp_path / "cache" / "p.bin").stat().st_size > 0


def test_a_cache_directory_the_user_chose_caches_small_programs_unless_told_otherwise(tmp_path):
    # JAX caches only programs that took a second to compile unless told otherwise; a
    # run has dozens of smaller ones, so smjax lowers the threshold, also in a directory
    # the user chose, but keeps a threshold the user set
    probe = ("import jax; from smjax.core.compile_cache import enable_compilation_cache; "
             "print(enable_compilation_cache(), "
             "jax.config.jax_persistent_cache_min_compile_time_secs)")

    def answer(**extra):
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))}
        env |= {"JAX_PLATFORMS": "cpu", "JAX_COMPILATION_CACHE_DIR": str(tmp_path)} | extra
        out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                             text=True, check=True).stdout.split()
        return out[0], float(out[1])

    assert answer() == (str(tmp_path), 0.0)
    assert answer(JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="2.5") == (str(tmp_path), 2.5)


def _flags_after_import(**env_vars) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "SMJAX_XLA_WORKAROUND")}
    env.update(PYTHONPATH=str(ROOT), **env_vars)
    out = subprocess.run([sys.executable, "-c", "import os, smjax; print(os.environ.get('XLA_FLAGS'))"],
                         env=env, capture_output=True, text=True, check=True, timeout=120)
    return out.stdout.strip()


def test_import_sets_the_cpu_flags_and_keeps_a_users_own():
    flags = _flags_after_import()
    assert "--xla_cpu_enable_concurrency_optimized_scheduler=false" in flags
    assert "--xla_cpu_experimental_ynn_fusion_type=" in flags.split()  # YNNPACK's dots off
    mine = "--xla_cpu_experimental_ynn_fusion_type=individual_dot"
    flags = _flags_after_import(XLA_FLAGS=mine).split()
    assert mine in flags and flags.count(mine) == 1
    assert not any(f == "--xla_cpu_experimental_ynn_fusion_type=" for f in flags)
    assert _flags_after_import(SMJAX_XLA_WORKAROUND="0", XLA_FLAGS="--xla_dump_to=x") == \
        "--xla_dump_to=x"
