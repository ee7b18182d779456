"""Fetch's dependencies (MuJoCo MJX, brax) are the ``fetch`` extra: without them every other
environment works, and asking for a Fetch task says what to install."""
from __future__ import annotations

import json
import os
import subprocess
import sys

# MuJoCo and brax made unimportable, as in an install without the ``fetch`` extra
_WITHOUT_MUJOCO = """
import sys
sys.modules["mujoco"] = None
sys.modules["brax"] = None
"""


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    return subprocess.run([sys.executable, "-c", _WITHOUT_MUJOCO + code, *args], env=env,
                          capture_output=True, text=True, timeout=300)


def test_without_mujoco_craft_and_football_work_and_fetch_says_what_to_install():
    out = _run("""
import json, smjax
env, params = smjax.make("craft/get_gem")
smjax.make("football/11v11_easy")
try:
    smjax.make("fetch/stack3")
    raise SystemExit("fetch/stack3 was made without MuJoCo")
except KeyError as err:
    print(json.dumps({"error": err.args[0], "tasks": sorted(smjax.registry())}))
""")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert "fetch/stack3" in result["error"] and "pip install 'smjax[fetch]'" in result["error"]
    assert "craft/get_gem" in result["tasks"] and "football/11v11_easy" in result["tasks"]
    assert not any(t.startswith("fetch/") for t in result["tasks"])


def test_without_mujoco_the_cli_lists_fetch_as_not_available_and_refuses_its_tasks_clearly():
    cli = "import runpy; sys.argv = ['smjax'] + sys.argv[1:]; runpy.run_module('smjax', run_name='__main__')"
    listed = _run(cli, "list")
    assert listed.returncode == 0, listed.stderr
    lines = listed.stdout.splitlines()
    assert any(line.startswith("craft/get_gem") for line in lines)
    assert any(line.startswith("fetch/...") and "smjax[fetch]" in line for line in lines)
    only = _run(cli, "list", "fetch")
    assert only.returncode == 0 and "smjax[fetch]" in only.stdout, only.stderr
    refused = _run(cli, "train", "fetch/stack1", "--seeds", "1")
    assert refused.returncode == 2
    assert "not available" in refused.stderr and "pip install 'smjax[fetch]'" in refused.stderr
    assert "Traceback" not in refused.stderr
