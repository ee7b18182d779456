"""resolve_config merges a run's configuration sources in one order; the trainer's host
state round-trips through the checkpoint's JSON layout, and one lacking a counter is named;
the device's running-success window gives what float64 host lists of its batches give.
Fast: only small programs compile."""
import json
import random

import jax
import numpy as np
import pytest

from smjax.train import ConfigError, TrainConfig
from smjax.train.config import RUN_SETTINGS, resolve_config
from smjax.train.plans import LevelPlan
from smjax.train.run import run_identity
from smjax.train.state import SuccessWindow, TrainerState, missing_counter


def test_sources_override_in_order(tmp_path):
    saved = {"task": "craft/get_wood", "seeds": [0], "num_envs": 8, "threshold": 0.5,
             "gamma": 0.9, "agent": {"learning_rate": 1e-3, "ent_coef": 0.1}}
    file = tmp_path / "cfg.yaml"
    file.write_text("threshold: 0.6\ngamma: 0.95\n")
    cfg = resolve_config(saved_run=saved, file=file, sets={"gamma": 0.97},
                         agent={"ent_coef": "0.2"})
    assert (cfg.num_envs, cfg.threshold, cfg.gamma) == (8, 0.6, 0.97)
    assert cfg.agent == {"learning_rate": 1e-3, "ent_coef": 0.2}  # merged, parsed
    assert resolve_config() == TrainConfig()
    base = TrainConfig(num_envs=4, agent={"hidden_sizes": (16, 16)})
    assert resolve_config(base).agent == {"hidden_sizes": [16, 16]}  # as JSON stores it
    assert resolve_config(base, sets={"threshold": 0.7}).num_envs == 4
    with pytest.raises(ConfigError, match="--set gamma=0.5"):
        resolve_config(agent={"gamma": 0.5})


def test_the_shipped_config_files_load_and_build_their_learner():
    # every preset under configs/ is a valid TrainConfig whose agent settings PPO accepts,
    # and a flag still wins over the file
    from pathlib import Path

    from smjax.agents import make_agent

    files = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
    assert files
    for file in files:
        cfg = resolve_config(file=file)
        make_agent(cfg.algo, **cfg.agent)
    fast = resolve_config(file=files[0].with_name("craft_fast.yaml"),
                          sets={"finetune_max_episodes": 12000})
    assert fast.agent == {"update_epochs": 8} and fast.finetune_max_episodes == 12000


def test_a_config_resolves_its_levels_and_learner_once_when_it_is_made():
    cfg = TrainConfig(gamma=0.95, agent={"hidden_sizes": (16, 16)},
                      levels={"give_key": {"threshold": np.float32(0.5), "gamma": 0.9}})
    assert cfg.agent == {"hidden_sizes": [16, 16]}  # as JSON stores it, without resolve_config
    key, other = cfg.for_level("give_key"), cfg.for_level("open_door")
    assert (key.threshold, key.gamma, key.success_window) == (0.5, 0.9, cfg.success_window)
    assert (other.threshold, other.gamma) == (cfg.threshold, 0.95)
    assert cfg.for_level("give_key") is key  # looked up, not made again
    assert cfg.window_slots == cfg.success_window


def test_resolve_run_checks_level_names_and_records_the_reachable_root(tmp_path):
    import smjax
    from smjax.train.plans import resolve_run

    env, _ = smjax.make("craft/make_bench", observation="none")
    cfg = TrainConfig(hierarchy="recipe", levels={"give_hammer": {"threshold": 0.9}})
    with pytest.warns(UserWarning, match="root level ends at 0.72"):
        plan = resolve_run(env, cfg)
    assert plan.cfg.levels == {"give_hammer": {"threshold": 0.9},
                               "make_bench": {"threshold": pytest.approx(0.72)}}
    assert plan.plans[0].name == "make_bench" and plan.hierarchy_name == "recipe"
    with pytest.raises(ConfigError, match="does not train"):
        resolve_run(env, TrainConfig(hierarchy="recipe", threshold=0.5,
                                     levels={"give_hamer": {"threshold": 0.5}}))


def test_settings_that_do_not_change_results_are_not_the_run_identity():
    identity = run_identity("craft/get_wood", TrainConfig(tensorboard=True), [0], {})
    assert not set(RUN_SETTINGS) & set(identity)
    assert run_identity("craft/get_wood", TrainConfig(checkpoint_every=1.0), [0], {}) == \
        run_identity("craft/get_wood", TrainConfig(), [0], {})


def test_host_state_round_trips_through_the_checkpoint_layout():
    plans = [LevelPlan("root", 0, 0, 2), LevelPlan("get_wood", 1, 0, 1)]
    st = TrainerState.new(plans, 2)
    # per update: environment episodes, the window's batch totals (newest first) and its
    # episodes (0: not full)
    assert st.level[1].count([3, 4], [[1.0, 0.0], [2.0, 1.0]], [0, 5], 64) == \
        [(3, 64, None), (7, 128, 0.6)]
    st.level[1].record_gate({"success": [0.0, 0.75], "uncalled": [0.0, 0.25],
                             "env_steps": [0, 99]}, 1, 12)
    st.finish_level(1)
    st.finetune[0].turns.append({"template": "root", "episodes": 5, "running_success": None})
    host = json.loads(json.dumps(st.to_json()))
    assert host["stage"] == [0, 1] and host["episodes"] == [0, 7]
    assert host["levels"][0]["gate_success"] == [None, 0.75]
    assert host["levels"][0]["gate_uncalled"] == [None, 0.25]
    assert host["finetune"]["turns"] == [[{"template": "root", "episodes": 5,
                                           "running_success": None}], []]
    assert TrainerState.from_json(host) == st
    assert missing_counter(host, 2) is None


def test_a_host_state_lacking_a_counter_is_named():
    """Every counter and level record ``to_json`` writes, over every seed, is needed to
    resume: one missing (or of another length) is named, before ``from_json`` reads it."""
    plans = [LevelPlan("root", 0, 0, 2), LevelPlan("get_wood", 1, 0, 1)]
    host = json.loads(json.dumps(TrainerState.new(plans, 2).to_json()))
    assert missing_counter(host, 2) is None
    assert "over its 3 seeds" in missing_counter(host, 3)
    for damage, name in ((lambda h: h.pop("gate_uncalled"), "counter gate_uncalled "),
                         (lambda h: h["levels"][1].pop("gate_uncalled"),
                          "counter levels[1] gate_uncalled "),
                         (lambda h: h["finetune"].pop("baseline"), "counter finetune baseline "),
                         (lambda h: h["started"].pop(), "counter started ")):
        damaged = json.loads(json.dumps(host))
        damage(damaged)
        assert name in missing_counter(damaged, 2)


def _append_window(history: list, total: float, count: int, window: int) -> float | None:
    """A host list of ``[total, count]`` batches, trimmed to the window, summed in float64:
    the reference."""
    if count:
        history.append([total, count])
    total, seen, keep = 0.0, 0, 0
    for s, c in reversed(history):
        total, seen, keep = total + s, seen + c, keep + 1
        if seen >= window:
            break
    del history[:len(history) - keep]
    return total / seen if seen >= window else None


_push = jax.jit(jax.vmap(SuccessWindow.push))


def _running(win, total, count, size):
    """One push for one seed, read as the host reads it (``_Counters._count``)."""
    win, (batches, seen) = _push(win, np.float32([total]), np.int32([count]), np.int32([size]))
    st = TrainerState.new([], 1)
    return win, st.level[0].count([0], np.asarray(batches), np.asarray(seen), 1)[0][2]


def test_the_window_averages_whole_batches_of_at_least_its_length():
    win = SuccessWindow.empty(1, 4)
    for total, count, expected in ((1.0, 2, None), (0.0, 0, None),  # no episodes: no batch
                                   (3.0, 3, 4.0 / 5), (4.0, 4, 1.0), (0.0, 0, 1.0)):
        win, running = _running(win, total, count, 4)
        assert running == expected


@pytest.mark.parametrize("size,slots", [(1, 1), (5, 5), (7, 12), (16, 16)])
def test_the_device_window_equals_the_host_lists(size, slots):
    """The same running success, bit for bit, as the float64 host lists, for binary and
    fractional successes (float32 batch totals), through wrap-arounds of the ring and
    empty updates."""
    rng = random.Random(size * 100 + slots)
    win, history = SuccessWindow.empty(1, slots), []
    for step in range(300):
        count = rng.choice([0, 1, 1, 2, 3, size, size + 2])
        if step % 2:
            total = float(sum(rng.random() < 0.6 for _ in range(count)))
        else:  # e.g. craft's make_stick F_o: fractions, summed in float32 on the device
            total = float(np.float32(sum(rng.random() / 3 for _ in range(count))))
        win, running = _running(win, total, count, size)
        assert running == _append_window(history, total, count, size), step
