"""Hostile-input probes as tests: every bad input is refused in one line (exit code 2 from the
CLI, no traceback), override values are parsed strictly for every environment, and no
checkpoint is ever lost: not on a re-save, not under a second run into the same
directory, not under kills at random instants (the last is ``slow``).

Training runs here are tiny (the key-door corridor of ``hier_env``, a few chunks).
"""
from __future__ import annotations

import errno
import json
import os
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import smjax
from hier_env import make_keydoor
from _helpers import cli_answer
from smjax.cli import main
from smjax.cli_train import parse_value
from smjax.core.overrides import parse_bool, parse_float, parse_int
from smjax.core.registry import get_entry
from smjax.train import TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.config import ConfigError
from smjax.train.outdir import LOCK_NAME, OutDirError, prepare_out_dir
from smjax.train.run import run

TINY = dict(num_envs=8, rollout_ticks=8, updates_per_chunk=2, max_episodes_per_level=300,
            success_window=32, gate_envs=8, eval_envs=8, checkpoint_every=0.0,
            finetune_max_episodes=100, finetune_turn_episodes=50)
SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
from hier_env import make_keydoor
from smjax.train import TrainConfig
from smjax.train.run import run
run(make_keydoor(), TrainConfig(**{cfg!r}), [0, 1], {out!r}, progress=False, resume={resume!r})
"""
ROOT = os.geteuid() == 0  # permissions do not bind root


def _start(out: Path, cfg: dict, resume: bool = False) -> subprocess.Popen:
    code = SCRIPT.format(tests=str(Path(__file__).parent), cfg=cfg, out=str(out), resume=resume)
    return subprocess.Popen([sys.executable, "-c", code], env=dict(os.environ, JAX_PLATFORMS="cpu"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


# ------------------------------------------------------------- strict override parsing
@pytest.mark.parametrize("word, value", [("true", True), ("False", False), ("no", False),
                                         ("OFF", False), ("1", True), (0, False), ("yes", True)])
def test_booleans_accept_only_their_words(word, value):
    assert parse_bool("x", word) is value


@pytest.mark.parametrize("bad", ["maybe", "", 2, 0.5, None, "nan", [True]])
def test_booleans_refuse_everything_else(bad):
    with pytest.raises(ValueError, match="x must be true or false"):
        parse_bool("x", bad)


def test_numbers_are_integral_finite_and_in_range():
    assert parse_int("n", 3.0) == 3 and parse_int("n", "7") == 7
    for bad in (2.7, float("nan"), True, "2.5", [1]):
        with pytest.raises(ValueError, match="n must be an integer"):
            parse_int("n", bad)
    with pytest.raises(ValueError, match=r"in \[1, 10\], got 0"):
        parse_int("n", 0, 1, 10)
    with pytest.raises(ValueError, match="finite"):
        parse_float("f", "inf")


def test_football_overrides_are_strict():
    for word in ("False", "no", "off", "0", False):
        env, params = smjax.make("football/11v11_easy", checkpoint_reward=word)
        assert not bool(params.checkpoint_reward)
    with pytest.raises(ValueError, match="game_length"):
        smjax.make("football/11v11_easy", game_length=2.9)
    with pytest.raises(ValueError, match="checkpoint_reward"):
        smjax.make("football/11v11_easy", checkpoint_reward="perhaps")


def test_fetch_overrides_are_strict():
    env, _ = smjax.make("fetch/stack1", obs_include_goals="False")
    assert env.config.obs_include_goals is False
    for bad in (dict(timestep=float("nan")), dict(solver_iterations=0), dict(substeps=2.7),
                dict(max_steps=1.5), dict(max_steps=2**31)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            smjax.make("fetch/stack1", **bad)


def test_craft_maps_refuse_bad_step_caps_and_tasks():
    from smjax.envs.craft import REFERENCE_GEM_MAP, from_ascii

    for bad in (0, -1, 1.5, 2**31):
        with pytest.raises(ValueError, match="max_steps"):
            from_ascii(REFERENCE_GEM_MAP, max_steps=bad)
    with pytest.raises(ValueError, match="unknown craft task"):
        from_ascii(REFERENCE_GEM_MAP, task=["get_gem"])
    no_gem = REFERENCE_GEM_MAP.replace("E", ".")
    with pytest.raises(ValueError, match=r"holds no gem \('E'\), which task 'get_gem' needs: it can never succeed"):
        from_ascii(no_gem, task="get_gem")
    with pytest.raises(ValueError, match="holds no wood"):
        from_ascii(REFERENCE_GEM_MAP.replace("w", "."), task="get_wood")
    from_ascii(no_gem, task="make_stick")  # a task the map can be for is fine


FAMILIES = ("craft/get_wood", "fetch/stack1", "football/11v11_easy")
TEXT = st.one_of(st.sampled_from(["true", "no", "off", "NaN", "Infinity", "-1", "0", "1.5", "3",
                                  "2.9", "1e9", "[]", "{}", "null", "paper", "compact", ""]),
                 st.text(max_size=8))


@pytest.mark.parametrize("task", FAMILIES)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_fuzzed_override_strings_are_parsed_or_refused(task, data):
    """Any text for any override of any environment: made with a valid value, or refused
    with ValueError/TypeError, never a crash or a silently converted value."""
    entry = get_entry(task)
    name = data.draw(st.sampled_from(entry.override_names))
    text = data.draw(TEXT)
    value = parse_value(text)
    try:
        env, params = smjax.make(task, **{name: value})
    except (ValueError, TypeError):
        return
    if isinstance(value, str) and value.strip().lower() in ("true", "false", "no", "off", "yes", "on"):
        default = entry.factory.__kwdefaults__[name]
        assert isinstance(default, bool) or default is None, (name, text)


def test_every_registered_task_refuses_a_non_integral_integer():
    for task in smjax.registry():
        entry = get_entry(task)
        ints = [k for k in entry.override_names if "max_steps" == k or "game_length" == k]
        for k in ints:
            with pytest.raises(ValueError):
                smjax.make(task, **{k: 1.5})


# ------------------------------------------------------------- configs and flags: exit 2
def _train(tmp_path, *extra) -> list[str]:
    return ["train", "craft/get_wood", "--quiet", "--out", str(tmp_path / "r"), *extra]


@pytest.mark.parametrize("content, suffix, needle", [
    (None, ".yaml", "does not exist"), ("DIR", ".yaml", "is a directory"),
    ("num_envs: many\n", ".yaml", "num_envs"), ("", ".yaml", "mapping"),
    ("- 1\n- 2\n", ".yaml", "mapping"), ("{bad json", ".json", "cannot be read or parsed"),
    ("gate: perhaps\n", ".yml", "gate"),
    ("success_window: 500\nmax_episodes_per_level: 400\n", ".yaml", "success_window")])
def test_config_file_errors_are_one_line(tmp_path, capsys, content, suffix, needle):
    path = tmp_path / f"c{suffix}"
    if content == "DIR":
        path.mkdir()
    elif content is not None:
        path.write_text(content)
    code, err = cli_answer(_train(tmp_path, "--config", str(path)), capsys)
    assert code == 2 and needle in err and str(path) in err and len(err.strip().splitlines()) <= 2


@pytest.mark.parametrize("extra, needle", [
    (["--agent", "gamma=0.5"], "--set gamma=0.5"), (["--set", "gate=perhaps"], "gate"),
    (["--set", "num_envs=2.5"], "num_envs"), (["--env", "fixed_map=maybe"], "fixed_map"),
    (["--env", "max_steps=0"], "max_steps"), (["--num-envs", "100000000"], "num_envs"),
    (["--num-envs", "3000000"], "num_envs"), (["--set", "noequals"], "KEY=VALUE"),
    (["--seeds", "0"], "--seeds"), (["--coordinator", "no-such-host.invalid:1234",
                                      "--num-processes", "2", "--process-id", "1",
                                      "--coordinator-timeout", "1"], "cannot be resolved"),
    (["--max-episodes", "100"], "'success_window' = 256 exceeds 'max_episodes_per_level' = 100"),
    (["--set", 'levels={"get_wood": {"max_episodes_per_level": 50}}'],
     "levels' for template 'get_wood'")])
def test_bad_flags_are_refused_before_compiling(tmp_path, capsys, extra, needle):
    t0 = time.perf_counter()
    code, err = cli_answer(_train(tmp_path, *extra), capsys)
    assert code == 2 and needle in err, err
    assert time.perf_counter() - t0 < 15  # no compile happened


def test_a_window_longer_than_the_episode_budget_is_refused():
    """success_window > max_episodes_per_level leaves the threshold unreachable: refused,
    for the whole run and for one level's overrides, naming both values and the fix."""
    with pytest.raises(ConfigError, match=r"'success_window' = 300 exceeds "
                                          r"'max_episodes_per_level' = 200.*lower success_window"):
        TrainConfig(success_window=300, max_episodes_per_level=200)
    with pytest.raises(ConfigError, match=r"levels' for template 'give_key'.*= 64 exceeds .* = 10"):
        TrainConfig(success_window=64, levels={"give_key": {"max_episodes_per_level": 10}})
    with pytest.raises(ConfigError, match="= 50000 exceeds 'max_episodes_per_level' = 40000"):
        TrainConfig(success_window=64, levels={"give_key": {"success_window": 50_000}})
    TrainConfig(success_window=10, max_episodes_per_level=10)  # a window the budget just fills
    ok = TrainConfig(success_window=64, levels={"give_key": {"max_episodes_per_level": 10,
                                                              "success_window": 10}})
    assert ok.for_level("give_key").success_window == 10


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_an_unreachable_coordinator_ends_in_one_line_within_its_timeout(tmp_path):
    """Left to JAX, an unreachable coordinator waits minutes and then aborts with a C++
    stack trace. Each way of not reaching the run ends with exit code 2 and one line, bounded by
    --coordinator-timeout: process 0 whose peers never join, a process whose coordinator
    does not answer, and a coordinator port already taken on process 0's host."""
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    cases = {"alone": ("0", _free_port(), "did not form within 3 s"),
             "no_answer": ("1", _free_port(), "did not answer within 3 s"),
             "port_taken": ("0", busy.getsockname()[1], "is already in use on this host")}
    t0, procs = time.perf_counter(), {}
    try:
        for name, (pid, port, _) in cases.items():  # in parallel: each mostly imports JAX
            procs[name] = subprocess.Popen(
                [sys.executable, "-m", "smjax", "train", "craft/get_wood", "--quiet", "--out",
                 str(tmp_path / name), "--coordinator", f"127.0.0.1:{port}", "--num-processes",
                 "2", "--process-id", pid, "--coordinator-timeout", "3"],
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                env=dict(os.environ, JAX_PLATFORMS="cpu"))
        for name, proc in procs.items():
            err = proc.communicate(timeout=300)[1]
            lines = err.strip().splitlines()
            assert proc.returncode == 2 and len(lines) == 1, (name, err[-3000:])
            assert cases[name][2] in lines[0] and "--coordinator" in lines[0], (name, lines)
        assert time.perf_counter() - t0 < 50  # JAX's own wait was 300 s; the flag's default 60
    finally:
        busy.close()
        for proc in procs.values():
            proc.kill()


def test_bad_output_paths_are_refused_before_compiling(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    t0 = time.perf_counter()
    code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(a_file)], capsys)
    assert code == 2 and "is a file" in err
    code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(a_file / "sub")], capsys)
    assert code == 2 and "cannot be created" in err
    elapsed = time.perf_counter() - t0
    assert elapsed < 5, elapsed
    if not ROOT:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
        try:
            code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(ro)], capsys)
            assert code == 2 and "not writable" in err
        finally:
            ro.chmod(0o755)


def test_resume_flag_contradictions(tmp_path, capsys):
    code, err = cli_answer(["train", "craft/get_wood", "--resume", str(tmp_path), "--overwrite"], capsys)
    assert code == 2 and "contradict" in err
    code, err = cli_answer(["train", "craft/get_wood", "--resume", str(tmp_path / "none")], capsys)
    assert code == 2 and "nothing to resume" in err


def test_a_directory_with_results_but_no_checkpoint_is_not_overwritten(tmp_path):
    out = tmp_path / "pruned"
    out.mkdir()
    (out / "results.json").write_text("{}")
    with pytest.raises(FileExistsError, match="already holds a run"):
        prepare_out_dir(out, resume=False, overwrite=False)
    prepare_out_dir(out, resume=False, overwrite=True).release()
    assert not (out / "results.json").exists()


# ------------------------------------------------------------- the lock
def test_a_held_lock_refuses_a_second_run_and_names_its_owner(tmp_path):
    out = tmp_path / "held"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from smjax.train.outdir import DirLock; from pathlib import Path;"
        f"DirLock(Path({str(out)!r})).acquire(); print('held', flush=True); time.sleep(60)")],
        stdout=subprocess.PIPE, text=True, cwd=str(Path(__file__).parent.parent))
    try:
        assert holder.stdout.readline().strip() == "held"
        t0 = time.perf_counter()
        with pytest.raises(OutDirError, match=f"pid {holder.pid}"):
            run(make_keydoor(), TrainConfig(**TINY), [0], out, progress=False)
        assert time.perf_counter() - t0 < 5
    finally:
        holder.kill()
        holder.wait()
    # the holder died without releasing: the kernel freed the flock, the file is stale,
    # and taking it over is a warning naming the dead owner
    with pytest.warns(UserWarning, match=f"took over the stale lock .*pid {holder.pid} "):
        lock = prepare_out_dir(out, resume=False, overwrite=False)
    assert lock.stale_owner["pid"] == holder.pid
    lock.release()
    assert not (out / LOCK_NAME).exists()


# ------------------------------------------------------------- checkpoints
def _arrays(x: float) -> dict:
    return {"a": np.full((3,), x, np.float32), "b": np.arange(4, dtype=np.int32)}


def _meta() -> dict:
    return {"run": {}, "host": {}}


def test_resaving_a_chunk_never_deletes_the_checkpoint_in_force(tmp_path, monkeypatch):
    ckpt.save_checkpoint(tmp_path, 3, _arrays(1.0), _meta())
    second = ckpt.save_checkpoint(tmp_path, 3, _arrays(2.0), _meta())
    assert second.name == "step-3.1" and ckpt.load_meta(tmp_path)["path"] == "step-3.1"
    assert (ckpt.checkpoint_dir(tmp_path) / "step-3").exists()  # the previous, kept
    # a write error during the next save keeps the one in force, readable
    import orbax.checkpoint as ocp

    def broken_save(self, path, *a, **k):
        Path(path).mkdir(parents=True)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ocp.StandardCheckpointer, "save", broken_save)
    with pytest.raises(ckpt.CheckpointError, match="disk full: .*previous checkpoint .* is kept; "
                                                   "free space, then --resume the run"):
        ckpt.save_checkpoint(tmp_path, 3, _arrays(3.0), _meta())
    monkeypatch.undo()
    assert ckpt.load_meta(tmp_path)["path"] == "step-3.1"
    np.testing.assert_array_equal(ckpt.load_arrays(tmp_path, _arrays(0.0))["a"], [2, 2, 2])
    from smjax.core.files import FILE_MODE  # what open() gives: 0644 under umask 022

    assert stat.S_IMODE((tmp_path / "checkpoints" / ckpt.LATEST).stat().st_mode) == FILE_MODE


def test_a_full_disk_is_not_reported_as_out_of_memory():
    """The I/O library calls a full disk RESOURCE_EXHAUSTED, as XLA calls a full device."""
    from smjax.cli_errors import user_message

    full = ckpt.CheckpointError(ckpt._write_failure(
        Path("/o/checkpoints/step-2"), Path("/o/checkpoints"),
        ValueError('RESOURCE_EXHAUSTED: Error writing local file "/o/x": Failed writing: No space '
                   'left on device')))
    assert user_message(full, "2 seed(s) x num_envs 16").startswith("disk full: could not write")
    oom = RuntimeError("RESOURCE_EXHAUSTED: Out of memory while trying to allocate 8.00GiB")
    assert user_message(oom, "2 seed(s) x num_envs 16").startswith(
        "out of memory with 2 seed(s) x num_envs 16")


@pytest.mark.parametrize("damage, needle", [
    (lambda d: (d / ckpt.LATEST).write_text("{trunc"), "not valid JSON"),
    (lambda d: (d / ckpt.LATEST).write_text('{"step": 1}'), "not a smjax checkpoint"),
    (lambda d: (d / ckpt.LATEST).write_text(json.dumps(
        {"step": 9, "path": "step-9", "meta": _meta()})), "does not exist"),
    (lambda d: [f.write_bytes(f.read_bytes()[:7]) for f in (d / "step-1").rglob("*")
                if f.is_file()], "corrupt")])
def test_damaged_checkpoints_are_one_line_errors(tmp_path, damage, needle):
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    damage(ckpt.checkpoint_dir(tmp_path))
    with pytest.raises(ckpt.CheckpointError, match=needle) as info:
        ckpt.load_arrays(tmp_path, _arrays(0.0))
    assert "\n" not in str(info.value)


def _read_only_errors(monkeypatch, folder: Path) -> None:
    """Writes into ``folder`` fail as on a read-only file system (EROFS), for root too."""
    real = Path.write_bytes

    def write_bytes(self, data):
        if self.resolve().parent == folder.resolve():
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real(self, data)

    real_open = os.open

    def os_open(path, flags, *a, **k):  # the probe creates its file with os.open
        if flags & os.O_CREAT and Path(path).resolve().parent == folder.resolve():
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, flags, *a, **k)

    monkeypatch.setattr(Path, "write_bytes", write_bytes)
    monkeypatch.setattr(os, "open", os_open)


@pytest.mark.parametrize("how", ["chmod", "erofs"])
def test_a_read_only_checkpoint_dir_fails_fast(tmp_path, monkeypatch, how):
    if how == "chmod" and ROOT:
        pytest.skip("permissions do not bind root (the erofs case covers it)")
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    d = ckpt.checkpoint_dir(tmp_path)
    if how == "chmod":
        d.chmod(stat.S_IRUSR | stat.S_IXUSR)
    else:
        _read_only_errors(monkeypatch, d)
    try:
        t0 = time.perf_counter()
        with pytest.raises(ckpt.CheckpointError, match="cannot write checkpoints to .*; make it "
                                                       "writable or choose another --out"):
            ckpt.save_checkpoint(tmp_path, 2, _arrays(2.0), _meta())
        assert time.perf_counter() - t0 < 5
    finally:
        d.chmod(0o755)
        monkeypatch.undo()
    assert ckpt.load_meta(tmp_path)["path"] == "step-1"  # the last good checkpoint is kept


def test_a_step_directory_orbax_cannot_create_fails_fast_and_quietly(tmp_path, monkeypatch, capfd):
    """The file system turns read-only (or full) between the write probe and orbax's own
    directory creation (in a background thread, whose failure can leave the writer threads
    waiting minutes): the save fails at once, in one error, printing nothing, and no orbax
    thread outlives it."""
    ckpt.save_checkpoint(tmp_path, 1, _arrays(1.0), _meta())
    real_mkdir = os.mkdir

    def mkdir(path, *a, **k):
        if ".orbax-checkpoint-tmp" in os.fsdecode(path):
            raise OSError(errno.EROFS, "Read-only file system", os.fsdecode(path))
        return real_mkdir(path, *a, **k)

    monkeypatch.setattr(os, "mkdir", mkdir)
    threads = {t.ident for t in threading.enumerate()}
    capfd.readouterr()
    t0 = time.perf_counter()
    with pytest.raises(ckpt.CheckpointError, match="Read-only file system.*previous checkpoint"):
        ckpt.save_checkpoint(tmp_path, 2, _arrays(2.0), _meta())
    assert time.perf_counter() - t0 < 10
    monkeypatch.undo()
    out, err = capfd.readouterr()
    assert out == "" and err == "", err[-2000:]
    left = [t for t in threading.enumerate() if t.ident not in threads and not t.daemon]
    assert not left, left
    assert ckpt.load_meta(tmp_path)["path"] == "step-1"
    np.testing.assert_array_equal(ckpt.load_arrays(tmp_path, _arrays(0.0))["a"], [1, 1, 1])


READ_ONLY_RUN = """
import builtins, errno, io, os, sys, time
from pathlib import Path
sys.path.insert(0, {tests!r})
from hier_env import make_keydoor
from smjax.cli import entry  # the smjax command
from smjax.core.registry import register

checkpoints, marker = Path({out!r}).resolve() / "checkpoints", Path({marker!r})
_open, _os_open, _mkdir = builtins.open, os.open, os.mkdir


def read_only(path) -> bool:
    \"\"\"Once the first checkpoint is in, the checkpoints folder is read-only (as if its
    file system were remounted so): every write under it fails with EROFS.\"\"\"
    try:
        inside = Path(os.path.abspath(os.fsdecode(path))).is_relative_to(checkpoints)
    except (TypeError, ValueError):
        return False
    if inside and os.path.exists(checkpoints / "latest.json"):
        if not os.path.exists(marker):
            with _open(marker, "w") as f:
                f.write(repr(time.time()))
        return True
    return False


def erofs(path):
    return OSError(errno.EROFS, "Read-only file system", os.fsdecode(path))


def ro_open(file, mode="r", *a, **k):
    if isinstance(file, (str, bytes, os.PathLike)) and set(mode) & set("wax+") and read_only(file):
        raise erofs(file)
    return _open(file, mode, *a, **k)


def ro_os_open(path, flags, *a, **k):
    if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT) and read_only(path):
        raise erofs(path)
    return _os_open(path, flags, *a, **k)


def ro_mkdir(path, *a, **k):
    if read_only(path):
        raise erofs(path)
    return _mkdir(path, *a, **k)


builtins.open = io.open = ro_open
os.open, os.mkdir = ro_os_open, ro_mkdir
register("test/keydoor", lambda: make_keydoor())
sys.exit(entry(["train", "test/keydoor", "--seeds", "2", "--out", {out!r}, "--quiet",
               *[f"--set={{k}}={{v}}" for k, v in {cfg!r}.items()]]))
"""


def test_a_run_whose_checkpoints_turn_read_only_ends_at_once_in_one_line(tmp_path):
    """The checkpoints folder turns read-only after the first checkpoint (every write under
    it fails with EROFS, root or not). The CLI process must end promptly (not wait on
    orbax's threads), with exit code 2, one line naming the folder and the fix, and the
    first checkpoint still usable."""
    out, marker = tmp_path / "ro", tmp_path / "first_refusal"
    cfg = TINY | {"gate": False, "max_episodes_per_level": 120}  # test_latest_never_dangles'
    code = READ_ONLY_RUN.format(tests=str(Path(__file__).parent), out=str(out),
                                marker=str(marker), cfg=cfg)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    ended = time.time()
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert lines[0].startswith("error: cannot write checkpoints to ") and "Read-only file " \
        "system; make it writable or choose another --out" in lines[0], lines[0]
    assert ended - float(marker.read_text()) < 30  # ends at once, not after orbax's timeout
    assert ckpt.load_meta(out) is not None  # the checkpoint written before is intact
    assert not (out / LOCK_NAME).exists()


# ------------------------------------------------------------- plot / render / bench
def test_plot_and_render_refuse_bad_inputs(tmp_path, capsys):
    empty, garbage = tmp_path / "empty", tmp_path / "garbage"
    for d, text in ((empty, ""), (garbage, "\x00\x01 not,a,csv\n1,2\n")):
        d.mkdir()
        (d / "curves.csv").write_text(text)
        code, err = cli_answer(["plot", str(d), "--out", str(tmp_path / "p.png")], capsys)
        assert code == 2 and "curves.csv" in err
    code, err = cli_answer(["render", "craft/get_wood", "--steps", "-3"], capsys)
    assert code == 2 and "--steps" in err


def test_plot_names_the_file_it_writes(tmp_path, capsys):
    run_dir = tmp_path / "r"
    run_dir.mkdir()
    (run_dir / "curves.csv").write_text(
        "seed,level,template,episodes,env_steps,avg_return\n0,1,root,10,80,0.5\n0,1,root,20,160,0.7\n")
    assert main(["plot", str(run_dir), "--out", str(tmp_path / "pl")]) == 0
    said = capsys.readouterr().out.strip()
    assert said.endswith("pl.png") and Path(said).exists()


def test_bench_stdout_holds_only_json(monkeypatch, capsys):
    import smjax.bench

    def noisy_bench(*a, **k):
        print("Failed to import warp: no module")  # what MuJoCo prints on import
        return {"steps_per_second": float("nan"), "env": "x"}

    monkeypatch.setattr(smjax.bench, "bench", noisy_bench)
    assert main(["bench", "craft/get_wood"]) == 0
    out = capsys.readouterr().out
    assert json.loads(out) == {"steps_per_second": None, "env": "x"}


# ------------------------------------------------------------- runs: watcher and concurrency
def _watch(latest: Path, stop: threading.Event, misses: list, seen: list) -> None:
    """Fail if latest.json ever points at a missing step (re-reading it, so a swap
    between the read and the check is not counted)."""
    while not stop.is_set():
        try:
            before = latest.read_text()
            path = latest.parent / json.loads(before)["path"]
        except (OSError, ValueError):
            continue
        ok = path.is_dir()
        if not ok and latest.read_text() == before:
            misses.append(path.name)
        seen.append(path.name)
        time.sleep(0.002)


def test_latest_never_dangles_and_a_second_run_is_refused(tmp_path, capsys):
    out = tmp_path / "shared"
    # no gate and no fine-tuning (two programs less to compile), a short budget: saves at
    # every chunk and boundary
    proc = _start(out, TINY | {"gate": False, "max_episodes_per_level": 120, "finetune": "off"})
    latest = out / "checkpoints" / ckpt.LATEST
    stop, misses, seen = threading.Event(), [], []
    watcher = threading.Thread(target=_watch, args=(latest, stop, misses, seen), daemon=True)
    watcher.start()
    try:
        deadline = time.time() + 240
        while not (out / LOCK_NAME).exists() and time.time() < deadline:
            time.sleep(0.05)
        t0 = time.perf_counter()
        code, err = cli_answer(["train", "craft/get_wood", "--quiet", "--out", str(out)], capsys)
        refused_in = time.perf_counter() - t0
        assert code == 2 and "in use by a running smjax run" in err and refused_in < 5
        assert proc.wait(timeout=600) == 0, proc.stderr.read()
    finally:
        stop.set()
        watcher.join()
        proc.kill()
    assert not misses, f"latest.json pointed at missing steps: {sorted(set(misses))}"
    assert len(set(seen)) >= 3  # the watcher really saw the run save
    results = json.loads((out / "results.json").read_text())
    assert results["seeds"] == [0, 1] and results["config"]["num_envs"] == TINY["num_envs"]
    assert not (out / LOCK_NAME).exists()
    print(f"second run refused in {refused_in:.2f} s; watcher saw {len(set(seen))} steps")


@pytest.mark.slow
def test_kills_at_random_instants_never_lose_the_checkpoint(tmp_path):
    """>= 50 SIGKILLs at random instants of runs that save every chunk and at every level
    boundary; after each, the next process must resume from the checkpoint (an unusable
    one makes it fail), and ``load_meta`` must find a complete step."""
    rng = np.random.default_rng(18)
    cfg = TINY | {"max_episodes_per_level": 3000}
    kills, lost, out, runs = 0, 0, tmp_path / "run0", 0
    latest = lambda: out / "checkpoints" / ckpt.LATEST  # noqa: E731
    while kills < 50:
        before = latest().read_text() if latest().exists() else None
        if before is None and out.exists():  # killed before its first checkpoint: nothing to
            runs += 1                         # lose; a fresh directory (--overwrite's case)
            out = tmp_path / f"run{runs}"
        proc = _start(out, cfg, resume=before is not None)
        if rng.random() < 0.2:  # now and then during start-up or compile
            time.sleep(rng.uniform(0.0, 8.0))
        else:  # mostly once this process is saving: wait for its first save, then a bit
            deadline = time.time() + 180
            while proc.poll() is None and time.time() < deadline:
                if latest().exists() and latest().read_text() != before:
                    break
                time.sleep(0.01)
            time.sleep(rng.uniform(0.0, 1.5))
        ended = proc.poll() is not None
        if not ended:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            kills += 1
        elif proc.returncode != 0:  # the resume could not use the checkpoint
            lost += 1
            print(proc.stderr.read()[-2000:])
        if ended:  # finished (or failed): go on with a fresh run
            runs += 1
            out = tmp_path / f"run{runs}"
            continue
        if latest().exists():
            ckpt.load_meta(out)  # raises on a dangling or damaged latest.json
    print(f"{kills} kills, {lost} runs without a usable checkpoint, {runs} runs ended")
    assert lost == 0
