"""The saved policy: a run writes RUN/policy, ``smjax.load_policy`` restores it without a
trainer, it acts under jit and vmap, its evaluation repeats the run's final_success,
``smjax eval`` prints it, and every mismatch is one line and exit code 2."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import smjax
from _helpers import cli_answer
from smjax.cli import main
from smjax.policy import PolicyError, SavedPolicy, load_policy
from smjax.train import TrainConfig
from smjax.train.outdir import existing_run_files
from smjax.train.run import run

TASK = "user_tasks:userkd/open_door"  # the key-door world, registered by a test module
CFG = TrainConfig(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=200,
                  success_window=32, gate_envs=16, eval_envs=32, finetune_max_episodes=100,
                  finetune_turn_episodes=50, checkpoint_every=0.0)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("saved") / "run"
    res = run(TASK, CFG, [0, 1], out, progress=False)
    return out, json.loads((out / "results.json").read_text()), res


def test_a_run_saves_its_policy_beside_its_results(trained):
    out, results, _ = trained
    meta = json.loads((out / "policy" / "policy.json").read_text())
    assert (out / "policy" / "arrays.msgpack").stat().st_size > 1000
    assert meta["task"] == TASK and meta["seeds"] == [0, 1] and meta["hierarchy"] == "paper"
    assert meta["options"] == ["open_door", "give_key"]
    assert meta["config"] == results["config"]  # the config that made it
    assert meta["smjax_version"] == results["smjax_version"]
    assert meta["jax_version"] == jax.__version__
    assert meta["observation"]["shape"] and meta["learner"]["algo"] == "ppo"
    assert "policy" in existing_run_files(out)  # --overwrite replaces it with the rest


def test_the_loaded_policy_repeats_the_runs_final_evaluation(trained):
    out, results, _ = trained
    policy = smjax.load_policy(out)
    assert isinstance(policy, SavedPolicy) and policy.seeds == [0, 1]
    again = policy.evaluate()
    assert again["success"] == results["final_success"]
    assert again["return"] == results["final_return"]
    other = policy.evaluate(episodes=8, seed=5)
    assert other["episodes"] == 8 and len(other["success"]) == 2
    assert all(0.0 <= s <= 1.0 for s in other["success"])
    with pytest.raises(ValueError, match="episodes"):
        policy.evaluate(episodes=0)


def test_act_and_step_are_pure_functions_under_jit_and_vmap(trained):
    policy = load_policy(trained[0], task=TASK)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    one = policy.params(0)
    action = jax.jit(policy.act)(one, policy.reset(keys[0], num_envs=4), keys[1])
    assert action.shape == (4,) and ((0 <= action) & (action < 3)).all()
    # every seed's hierarchy at once: a vmap over the seed axis of params, carries and keys
    carries = jax.vmap(lambda k: policy.reset(k, 4))(keys)
    stepped, ends = jax.jit(jax.vmap(policy.step))(policy.params(), carries, keys)
    assert ends.reset.shape == (2, 4) and stepped.obs.shape == carries.obs.shape
    first, _ = jax.jit(policy.step)(one, jax.tree.map(lambda x: x[0], carries), keys[0])
    np.testing.assert_array_equal(first.obs, stepped.obs[0])
    with pytest.raises(ValueError, match="seed_index"):
        policy.params(2)


def test_smjax_eval_prints_the_success_of_every_seed(trained, capsys):
    out, results, _ = trained
    assert main(["eval", str(out)]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["success"] == results["final_success"] and line["seeds"] == [0, 1]
    assert line["mean_success"] == pytest.approx(np.mean(results["final_success"]))
    assert main(["eval", str(out), "--episodes", "8", "--seed", "3"]) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["episodes"] == 8
    code, err = cli_answer(["eval", str(out), "--episodes", "0"], capsys)
    assert code == 2 and "--episodes" in err, err


@pytest.fixture
def copied(trained, tmp_path):
    """A copy of the trained run's policy folder, to damage."""
    where = tmp_path / "run"
    shutil.copytree(trained[0] / "policy", where / "policy")
    return where


def _edit(run_dir: Path, **changes) -> None:
    path = run_dir / "policy" / "policy.json"
    meta = json.loads(path.read_text())
    for key, value in changes.items():
        section, _, field = key.partition("__")
        if field:
            meta[section][field] = value
        else:
            meta[section] = value
    path.write_text(json.dumps(meta))


def test_a_policy_saved_with_the_runners_tick_settings_still_loads(copied, trained):
    # policies saved while the runner held the tick's settings name them among its
    # keyword arguments and keep the discount there, not with the evaluation
    path = copied / "policy" / "policy.json"
    meta = json.loads(path.read_text())
    assert set(meta["runner"]) == {"reset_pool", "frozen_eval", "policy_memory"}
    gamma = meta["evaluation"].pop("gamma")
    meta["runner"].update(gamma=gamma, frozen_policy="sample", allow_teleport=True,
                          template_temperature=1.0)
    path.write_text(json.dumps(meta))
    policy = load_policy(copied)
    assert policy.gamma == gamma
    assert policy.evaluate()["success"] == trained[1]["final_success"]


@pytest.mark.parametrize("damage, needle", [
    (lambda d: _edit(d, format=99), "format 99"),
    (lambda d: _edit(d, kind="something"), "not a smjax policy"),
    (lambda d: (d / "policy" / "policy.json").write_text("{"), "damaged"),
    (lambda d: (d / "policy" / "arrays.msgpack").write_bytes(b"x"), "damaged"),
    (lambda d: (d / "policy" / "arrays.msgpack").unlink(), "cannot be read"),
    (lambda d: _edit(d, options=["open_door", "other"]), "has options"),
    (lambda d: _edit(d, observation__shape=[7]), "observations"),
    (lambda d: _edit(d, learner__agent={"hidden_sizes": [8]}), "saved parameter"),
    (lambda d: _edit(d, hierarchy="nope"), "unknown hierarchy 'nope'"),
    (lambda d: _edit(d, task="craft/get_wood"), "unknown hierarchy 'paper' for 'craft/get_wood'"),
    (lambda d: shutil.rmtree(d / "policy"), "holds no saved policy"),
], ids=["format", "kind", "json", "arrays", "no-arrays", "options", "observation", "learner",
        "hierarchy", "task", "missing"])
def test_a_mismatch_is_one_clear_line(copied, capsys, damage, needle):
    damage(copied)
    with pytest.raises(PolicyError, match=needle):
        load_policy(copied)
    code, err = cli_answer(["eval", str(copied)], capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err


def test_another_task_is_refused(trained, capsys):
    with pytest.raises(PolicyError, match="holds a policy for user_tasks:userkd/open_door, not"):
        load_policy(trained[0], task="craft/get_wood")
    code, err = cli_answer(["render", "craft/get_wood", "--policy", str(trained[0])], capsys)
    assert code == 2 and "not craft/get_wood" in err, err


def test_loading_needs_no_learners_until_asked():
    # importing smjax (an environment alone) loads neither the saved-policy code nor the
    # learners; smjax.load_policy imports them on first use
    code = ("import sys, smjax; print('smjax.policy' in sys.modules, "
            "'smjax.agents' in sys.modules, callable(smjax.load_policy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={"PATH": "/usr/bin:/bin", "JAX_PLATFORMS": "cpu",
                                          "PYTHONPATH": str(Path(smjax.__file__).parents[1])})
    assert out.stdout.split() == ["False", "False", "True"]
