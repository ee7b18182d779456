"""benchmarks/diagnose_hierarchy.py: its trace of lost episodes picks the episodes that ended
short of the task's best, groups their ticks into runs of one option on top and one inventory,
and shows the start state where the environment has a text form (Craft's map)."""
from __future__ import annotations

import json
from types import SimpleNamespace

import jax
import numpy as np

import smjax
from _helpers import load_benchmark
from smjax.cli import main
from smjax.envs.craft.ascii import to_ascii


def _load():
    return load_benchmark("diagnose_hierarchy")


def test_craft_describes_its_map_and_other_environments_may_not():
    env, params = smjax.make("craft/get_wood")
    _, state = env.reset(jax.random.key(3), params)
    text = env.describe(state, params)
    assert text == to_ascii(state) and text.count("@") == 1 and len(text.splitlines()) == 12
    football, fparams = smjax.make("football/11v11_easy")
    _, fstate = football.reset(jax.random.key(0), fparams)
    assert football.describe(fstate, fparams) is None


def test_trace_keeps_the_short_episodes_and_groups_their_ticks():
    diag = _load()
    env, params = smjax.make("craft/get_wood")
    starts = jax.vmap(lambda k: env.reset(k, params)[1])(jax.random.split(jax.random.key(0), 3))
    engine = SimpleNamespace(env=env, h=SimpleNamespace(success_ceiling=1.0,
                                                        option_names=("root", "give_wood")))
    T, B, K = 5, 3, 4
    top = np.zeros((T, B), np.int32)
    top[1:3, 0] = 1                        # env 0: root, give_wood for two ticks, root
    inventory = np.zeros((T, B, K), np.int32)
    inventory[3:, 0, 2] = 1                # ... which picked up one unit of item 2
    pos = np.tile(np.arange(T)[:, None, None], (1, B, 2)).astype(np.int32)
    finished = np.zeros((T, B), bool)
    success = np.zeros((T, B), np.float32)
    finished[3, 0], success[3, 0] = True, 0.5   # env 0 ends short of the best at tick 3
    finished[2, 1], success[2, 1] = True, 1.0   # env 1 succeeds: not traced
    # env 2 never ends within the trace: traced as still running
    text = diag.trace_lost(engine, starts, (top, inventory, pos, finished, success), 5,
                           ("a", "b", "wood", "d"))
    blocks = text.split("== episode ")[1:]
    assert [b.split(":")[0] for b in blocks] == ["0", "2"]
    assert "4 ticks, ended with success 0.50" in blocks[0]
    assert to_ascii(jax.tree.map(lambda x: x[0], starts)) in blocks[0]
    runs = [line.strip() for line in blocks[0].splitlines() if line.startswith("  ticks")]
    assert runs == ["ticks 0-0 root held={} pos (0, 0)..(0, 0)",
                    "ticks 1-2 give_wood held={} pos (1, 1)..(2, 2)",
                    "ticks 3-3 root held={'wood': 1} pos (3, 3)..(3, 3)"]
    assert "5 ticks, ran into the trace's end" in blocks[1]
    # only as many as asked for
    assert text.count("== episode") == 2
    one = diag.trace_lost(engine, starts, (top, inventory, pos, finished, success), 1, None)
    assert one.count("== episode") == 1 and "held={'2': 1}" in one


def test_trace_of_a_trained_run_from_the_command_line(tmp_path, capsys):
    out = tmp_path / "wood"
    assert main(["train", "craft/get_wood", "--seeds", "1", "--num-envs", "8", "--max-episodes",
                 "16", "--env", "observation=compact", "--set", "rollout_ticks=8", "--set",
                 "eval_envs=8", "--finetune", "off", "--set", "success_window=8", "--set",
                 "gate_envs=8", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    report = tmp_path / "report.json"
    # two ticks: (almost) no episode can finish, so at least three are traced
    assert _load().main([str(out), "--episodes", "8", "--max-ticks", "2", "--trace", "3",
                         "--json", str(report)]) == 0
    captured = capsys.readouterr()
    assert json.loads(report.read_text())["per_seed"][0]["unfinished"] >= 0.5
    assert captured.err.count("== episode") == 3
    assert captured.err.count("ticks 0-") == 3 and captured.err.count("@") == 3  # each its map
