"""Several processes joined with jax.distributed (on 127.0.0.1, CPU, gloo) train together.

Two processes with 2 virtual CPU devices each form a 4-device mesh; 4 seeds give
seed-only sharding (one seed per device), so the numbers are bitwise those of one
process with 4 virtual devices (and of 1 device: see test_sharding.py), fine-tuning
included; so are a sweep's, whose (point, seed) slots are just more seeds. Process 0
writes everything; process 1 runs in an empty working directory with its own --out and
must leave both untouched. A two-process run killed mid-level resumes (every process
restoring process 0's checkpoint) to the same results.
"""
import collections
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from smjax.train import distributed as dist
from smjax.train.sharding import training_mesh

TESTS = str(Path(__file__).parent)
# fine-tuning on, its budget small (two turns of 50 episodes) to keep the test short
CFG = dict(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=300,
           success_window=64, gate_envs=32, eval_envs=32, finetune="on",
           finetune_max_episodes=100, finetune_turn_episodes=50)
SEEDS = [0, 1, 2, 3]
SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
from smjax.train import distributed
joined = distributed.initialize(initialization_timeout=60)
import jax
from hier_env import make_keydoor
from smjax.train import TrainConfig
from smjax.train.run import run
assert joined == (jax.process_count() > 1)
run(make_keydoor(), TrainConfig(**{cfg!r}), {seeds!r}, {out!r}, progress=False, resume={resume!r},
    sweep={sweep!r})
"""
TIMING = ("wall_seconds", "compile_seconds")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(out: Path, cwd: Path, devices: int, cfg: dict, resume: bool = False,
           process: tuple[int, int, int] | None = None, seeds: list[int] = SEEDS,
           sweep: dict | None = None) -> subprocess.Popen:
    """One training process; ``process`` = (port, num_processes, process_id) joins a run."""
    env = dict(os.environ, JAX_PLATFORMS="cpu",
               XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    for name in (dist.ENV_COORDINATOR, dist.ENV_NUM_PROCESSES, dist.ENV_PROCESS_ID):
        env.pop(name, None)
    if process is not None:
        port, n, i = process
        env.update({dist.ENV_COORDINATOR: f"127.0.0.1:{port}", dist.ENV_NUM_PROCESSES: str(n),
                    dist.ENV_PROCESS_ID: str(i)})
    cwd.mkdir(parents=True, exist_ok=True)
    code = SCRIPT.format(tests=TESTS, cfg=cfg, out=str(out), resume=resume, seeds=seeds,
                         sweep=sweep)
    return subprocess.Popen([sys.executable, "-c", code], env=env, cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _wait(procs: list[subprocess.Popen], timeout: float = 600) -> None:
    # (a guard against a hang, not a speed check: on a loaded 2-core machine a two-process
    # run with fine-tuning has taken over 300 s; a process past it is ended, not left behind)
    for proc in procs:
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            for p in procs:
                p.kill()
            raise
        assert proc.returncode == 0, out[-3000:]


def _pair(tmp: Path, out0: Path, cfg: dict, resume: bool = False,
          **kw) -> list[subprocess.Popen]:
    port = _free_port()
    return [_start(out0, tmp / "cwd0", 2, cfg, resume, (port, 2, 0), **kw),
            _start(tmp / "p1_out", tmp / "cwd1", 2, cfg, resume, (port, 2, 1), **kw)]


def _results(out: Path) -> dict:
    return {k: v for k, v in json.loads((out / "results.json").read_text()).items() if k not in TIMING}


JOIN = """
import json
from smjax.train import distributed
assert distributed.initialize(initialization_timeout=60)
import jax
print(json.dumps({"processes": jax.process_count(), "index": jax.process_index(),
                  "devices": len(jax.devices()),
                  "agreed": distributed.broadcast_json({"from": jax.process_index()})}))
"""


def test_two_processes_join_and_agree(tmp_path):
    """The default suite's multi-process check: two processes join through
    ``distributed.initialize`` (the path the CLI takes) and agree on process 0's value.
    (Training together, which compiles for minutes: the slow tests below.)"""
    port, procs = _free_port(), []
    for i in range(2):
        env = dict(os.environ, JAX_PLATFORMS="cpu", XLA_FLAGS="--xla_force_host_platform_device_count=2",
                   **{dist.ENV_COORDINATOR: f"127.0.0.1:{port}", dist.ENV_NUM_PROCESSES: "2",
                      dist.ENV_PROCESS_ID: str(i)})
        procs.append(subprocess.Popen([sys.executable, "-c", JOIN], env=env, cwd=tmp_path,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    for i, proc in enumerate(procs):
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err[-3000:]
        assert json.loads(out.strip().splitlines()[-1]) == {
            "processes": 2, "index": i, "devices": 4, "agreed": {"from": 0}}


@pytest.mark.slow  # three processes compile a training run: minutes on a 2-core CI
def test_two_processes_equal_one_process(tmp_path):
    single = _start(tmp_path / "single", tmp_path / "cwd", 4, CFG)
    _wait([single])
    procs = _pair(tmp_path, tmp_path / "multi", CFG)
    _wait(procs)
    one, two = _results(tmp_path / "single"), _results(tmp_path / "multi")
    assert [lvl["template"] for lvl in two["levels"]] == ["open_door", "give_key"]
    assert two["levels"] == one["levels"]
    assert two["finetune"]["turns"] == one["finetune"]["turns"]  # it fine-tuned, in step
    assert two["final_success"] == one["final_success"]
    assert two == one
    assert (tmp_path / "multi" / "curves.csv").read_text() == (tmp_path / "single" / "curves.csv").read_text()
    assert (tmp_path / "multi" / "checkpoints" / "latest.json").exists()
    # process 1 wrote nothing: neither its --out nor anything in its working directory
    assert not (tmp_path / "p1_out").exists()
    assert list((tmp_path / "cwd1").iterdir()) == []


@pytest.mark.slow
def test_a_sweep_on_two_processes_equals_one_process(tmp_path):
    """2 points x 2 seeds: four slots on the seed axis, one per device as seeds are."""
    kw = dict(seeds=[0, 1], sweep={"agent.learning_rate": [3e-4, 1e-3]})
    cfg = CFG | {"max_episodes_per_level": 200}
    _wait([_start(tmp_path / "single", tmp_path / "cwd", 4, cfg, **kw)])
    _wait(_pair(tmp_path, tmp_path / "multi", cfg, **kw))

    def numbers(out: Path) -> list[dict]:
        sweep = json.loads((out / "sweep.json").read_text())
        return [{"overrides": p["overrides"], "results": {
            k: v for k, v in p["results"].items() if k not in TIMING}} for p in sweep["points"]]
    assert len(numbers(tmp_path / "multi")) == 2
    assert numbers(tmp_path / "multi") == numbers(tmp_path / "single")
    for p in range(2):
        assert _results(tmp_path / "multi" / f"point-{p}") == _results(tmp_path / "single" / f"point-{p}")
    assert not (tmp_path / "p1_out").exists()
    assert list((tmp_path / "cwd1").iterdir()) == []


@pytest.mark.slow
def test_two_processes_killed_then_resumed_equal_uninterrupted(tmp_path):
    cfg = CFG | {"max_episodes_per_level": 1500, "checkpoint_every": 0.0}
    straight = _start(tmp_path / "straight", tmp_path / "cwd", 4, cfg)
    _wait([straight])
    out = tmp_path / "killed"
    procs = _pair(tmp_path, out, cfg)
    latest, deadline = out / "checkpoints" / "latest.json", time.time() + 240
    while time.time() < deadline:  # a few checkpoints in, kill both mid-level
        if latest.exists() and json.loads(latest.read_text())["step"] >= 3:
            break
        if any(p.poll() is not None for p in procs):
            pytest.fail("training ended before it could be killed; lengthen the run")
        time.sleep(0.05)
    for p in procs:
        p.send_signal(signal.SIGKILL)
        p.wait()
    assert not (out / "results.json").exists()
    _wait(_pair(tmp_path, out, cfg, resume=True))
    assert _results(out) == _results(tmp_path / "straight")
    assert not (tmp_path / "p1_out").exists()


# ---- initialize: single process and bad input -----------------------------------------------
@pytest.fixture
def clean_env(monkeypatch):
    for name in (dist.ENV_COORDINATOR, dist.ENV_NUM_PROCESSES, dist.ENV_PROCESS_ID):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_single_process_does_nothing(clean_env):
    assert dist.initialize() is False
    assert dist.initialize(num_processes=1) is False
    assert dist.initialize("127.0.0.1:1234", 1, 0) is False
    assert dist.is_writer() and not dist.is_multiprocess()


@pytest.mark.parametrize("args, message", [
    (("127.0.0.1:1234", 2, 2), r"process_id must be in 0\.\.1"),
    (("127.0.0.1:1234", 2, -1), "process_id must be >= 0"),
    (("127.0.0.1:1234", 0, 0), "num_processes must be >= 1"),
    (("127.0.0.1", 2, 0), "HOST:PORT"),
    (("127.0.0.1:http", 2, 0), "HOST:PORT"),
    (("127.0.0.1:70000", 2, 0), "port must be in 1..65535"),
    ((":1234", 2, 0), "HOST:PORT"),
    ((None, 2, 0), "missing coordinator"),
    (("127.0.0.1:1234", None, 1), "missing num_processes"),
    (("127.0.0.1:1234", 2, None), "missing process_id"),
    ((None, 1, 1), r"process_id must be in 0\.\.0"),
])
def test_bad_arguments_are_refused(clean_env, args, message):
    with pytest.raises(ValueError, match=message):
        dist.initialize(*args)


def test_environment_variables_are_read_and_checked(clean_env):
    clean_env.setenv(dist.ENV_NUM_PROCESSES, "two")
    with pytest.raises(ValueError, match="JAX_NUM_PROCESSES.*'two'"):
        dist.initialize()
    clean_env.setenv(dist.ENV_NUM_PROCESSES, "2")
    clean_env.setenv(dist.ENV_PROCESS_ID, "5")
    with pytest.raises(ValueError, match=r"process_id must be in 0\.\.1"):
        dist.initialize()
    clean_env.setenv(dist.ENV_PROCESS_ID, "1")
    clean_env.setenv(dist.ENV_COORDINATOR, "host-without-port")
    with pytest.raises(ValueError, match="HOST:PORT"):
        dist.initialize()
    assert dist.resolve("[::1]:8476", None, None)[0] == "[::1]:8476"
    clean_env.setenv(dist.ENV_COORDINATOR, "node-1.cluster:8476")
    assert dist.resolve() == ("node-1.cluster:8476", 2, 1)
    # explicit values win over the environment
    assert dist.resolve("10.0.0.1:99", 4, 3) == ("10.0.0.1:99", 4, 3)


def test_cli_reports_bad_distributed_flags(clean_env, capsys):
    from smjax.cli import main

    assert main(["train", "craft/get_wood", "--coordinator", "127.0.0.1:1234",
                 "--num-processes", "2", "--process-id", "3"]) == 2
    assert "process_id must be in 0..1" in capsys.readouterr().err
    assert main(["train", "craft/get_wood", "--coordinator", "127.0.0.1:1234",
                 "--num-processes", "2", "--process-id", "0", "--local-device-ids", "0,x"]) == 2
    assert "--local-device-ids" in capsys.readouterr().err


@settings(max_examples=60, deadline=None)
@given(num=st.integers(-2, 6), pid=st.integers(-2, 6))
def test_process_ids_accepted_exactly_when_in_range(num, pid):
    if num >= 1 and 0 <= pid < num:
        assert dist.resolve("127.0.0.1:1234", num, pid) == ("127.0.0.1:1234", num, pid)
    else:
        with pytest.raises(ValueError, match="process_id|num_processes"):
            dist.resolve("127.0.0.1:1234", num, pid)


@settings(max_examples=60, deadline=None)
@given(port=st.integers(-5, 70000), host=st.sampled_from(["127.0.0.1", "node-3", "[::1]", "a.b.c"]))
def test_addresses_need_a_port_in_range(port, host):
    address = f"{host}:{port}"
    if 1 <= port <= 65535:
        assert dist.check_address(address) == address
    else:
        with pytest.raises(ValueError, match="HOST:PORT|port must be"):
            dist.check_address(address)


class _FakeDevice:
    """Enough of a device for the mesh arithmetic (several processes cannot be real here)."""

    platform = "cpu"

    def __init__(self, id_: int, process_index: int):
        self.id, self.process_index = id_, process_index

    def __repr__(self):
        return f"dev{self.id}@p{self.process_index}"


@settings(max_examples=80, deadline=None)
@given(processes=st.integers(2, 4), per_process=st.integers(1, 4), seeds=st.integers(1, 16),
       envs=st.integers(1, 64))
def test_multiprocess_mesh_gives_every_process_an_equal_share(processes, per_process, seeds, envs):
    n = processes * per_process
    devices = [_FakeDevice(i, i // per_process) for i in range(n)]
    g = math.gcd(seeds, n)
    possible = any(g % a == 0 and envs % b == 0 and (a * b) % processes == 0 and n % (a * b) == 0
                   for a in range(1, g + 1) for b in range(1, n // a + 1))
    if not possible:
        with pytest.raises(ValueError, match="cannot spread"):
            training_mesh(seeds, envs, devices)
        return
    mesh = training_mesh(seeds, envs, devices)
    seed_ways, env_ways = mesh.shape["seed"], mesh.shape["env"]
    assert seeds % seed_ways == 0 and envs % env_ways == 0
    used = list(mesh.devices.flat)
    assert len({d.id for d in used}) == len(used)
    shares = collections.Counter(d.process_index for d in used)
    assert set(shares) == set(range(processes)) and len(set(shares.values())) == 1
    if seeds % n == 0:  # seed-only sharding: bitwise the single-device numbers
        assert (seed_ways, env_ways) == (n, 1)
