"""Fine-tuning: after the levels, the learned hierarchy keeps learning without teleports."""
import dataclasses
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _helpers import MachineLost, lose_machine_after_save, with_format
from hier_env import KeyDoor, make_keydoor
from smjax.agents import make_agent
from smjax.train import ConfigError, TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.run import run
from smjax.train.hooks import CheckpointHook
from smjax.train.seed_arrays import freeze

CFG = dict(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=1500,
           success_window=64, gate_envs=64, eval_envs=64, finetune_max_episodes=1500,
           finetune_turn_episodes=500, finetune_mode="turns")  # (joint: tests/test_joint.py)


class FarTeleport(KeyDoor):
    """``give_key``'s teleport also carries the agent to the cell left of the door, while
    a learned ``give_key`` leaves it at the key: a root trained with the teleport learns
    "call give_key, step right, USE" and fails once the teleport is gone, unless it
    learns, without teleports, to walk to the door."""

    name = "test/keydoor_far_teleport"

    def templates(self):
        out = super().templates()

        def beside_the_door(key, state, params):  # then LEFT: one cell left of the door
            return state.replace(pos=state.door_pos, has_key=True), jnp.asarray(0)

        out["give_key"] = dataclasses.replace(out["give_key"], teleport=beside_the_door)
        return out


def _strip_timing(res: dict) -> dict:
    return {k: v for k, v in res.items() if k not in ("wall_seconds", "compile_seconds", "_raw")}


@pytest.fixture(scope="module")
def far_teleport_run():
    env = FarTeleport()
    return run((env, env.default_params), TrainConfig(**CFG), [0, 1], progress=False)


def test_finetuning_fixes_what_the_teleport_hid(far_teleport_run):
    assert_the_teleport_fixed(far_teleport_run)


def assert_the_teleport_fixed(res: dict) -> None:
    """The levels learned, their root fails without the teleport, fine-tuning mends it."""
    before = np.array(res["finetune"]["final_success_before"])
    after = np.array(res["final_success"])
    assert all(r for rec in res["levels"] for r in rec["reached"])  # the levels did learn
    assert before.mean() < 0.6, before  # with the teleport gone the levels' root fails
    assert after.mean() >= before.mean() + 0.3, (before, after)


def test_results_keep_the_contract(far_teleport_run):
    res = far_teleport_run
    ft = res["finetune"]
    for key in ("episodes", "env_steps", "gate_env_steps", "reached", "final_success_before",
                "turns", "task_running_success"):
        assert len(ft[key]) == 2, key
    for s in range(2):
        levels = sum(rec["episodes"][s] for rec in res["levels"])
        assert res["episodes_to_threshold"][s] == levels  # the paper's count: levels only
        assert res["total_episodes"][s] == levels + ft["episodes"][s]
        assert 0 < ft["episodes"][s] <= CFG["finetune_max_episodes"] + 16 * 16 * 2
        # turns go top-down and round again: the root, give_key, the root, ...
        names = [t["template"] for t in ft["turns"][s]]
        assert names[:2] == ["open_door", "give_key"][:len(names[:2])]
        assert all(t["episodes"] <= CFG["finetune_turn_episodes"] + 16 * 16 * 2
                   for t in ft["turns"][s])
        # an option plays right after a turn that left it below the option threshold
        for a, b in zip(ft["turns"][s], ft["turns"][s][1:]):
            if a["template"] == "give_key" and (a["running_success"] or 0) < 0.95:
                assert b["template"] == "open_door"
    assert res["eval_policy"] == "sample"
    # the run's own mode alone unless eval_policies says "all"
    assert res["final_success_by_policy"] == {"sample": res["final_success"]}


def test_finetune_off_and_bad_values():
    assert TrainConfig().fine_tuning.on and not TrainConfig(method="flat").fine_tuning.on
    assert TrainConfig(method="flat", finetune="on").fine_tuning.on
    assert not TrainConfig(finetune="off").fine_tuning.on
    for field, value in (("finetune", "maybe"), ("finetune_threshold", 0.0),
                         ("finetune_option_threshold", 1.5), ("finetune_max_episodes", 0),
                         ("finetune_turn_episodes", -3), ("finetune_max_rest", -1),
                         ("finetune_max_rest", 1.5)):
        with pytest.raises(ConfigError, match=field):
            TrainConfig(**{field: value})


SMALL = dict(finetune_mode="turns", num_envs=8, rollout_ticks=8, updates_per_chunk=2, success_window=32, gate_envs=16,
             eval_envs=16, max_episodes_per_level=150, finetune_max_episodes=240,
             finetune_turn_episodes=80)


def _banks_equal(a, b) -> bool:
    return all(jax.tree.leaves(jax.tree.map(lambda x, y: bool((np.asarray(x) == np.asarray(y)).all()),
                                            a, b)))


def _record_levels_bank(monkeypatch, before: float) -> list:
    """Force final_success_before to ``before``; the returned list receives the levels'
    bank as fine-tuning starts."""
    from smjax.train.finetune import FinetuneStage

    levels_banks = []
    real = FinetuneStage.enter

    def enter(self, st, seeds):
        real(self, st, seeds)
        for s in seeds:
            st.finetune[s].success_before = before
        if seeds:
            levels_banks.append(jax.tree.map(np.asarray, self.slots.arrays.bank))

    monkeypatch.setattr(FinetuneStage, "enter", enter)
    return levels_banks


@pytest.mark.parametrize("before", [2.0, -1.0])
def test_the_phase_hands_back_the_better_hierarchy(monkeypatch, before):
    # final_success_before forced above anything reachable (2.0) or below (-1.0): where no
    # gate passed, the phase must hand back the levels' bank, or keep the fine-tuned one
    levels_banks = _record_levels_bank(monkeypatch, before)
    cfg = TrainConfig(**(SMALL | {"finetune_threshold": 1.0}))  # no gate passes
    res = run(make_keydoor(), cfg, [0], progress=False)
    ft = res["finetune"]
    assert ft["reached"] == [False] and ft["baseline"] == [True]
    assert 0.0 <= ft["check_success"][0] <= 1.0
    assert ft["gate_env_steps"][0] > 0  # the check's episodes are counted
    assert ft["kept"] == (["levels"] if before > 1 else ["fine-tuned"])
    assert len(levels_banks) == 1
    assert _banks_equal(res["_raw"]["bank"], levels_banks[0]) == (before > 1)


def test_finetune_agent_sets_the_turns_hyper_parameters(monkeypatch):
    # at a learning rate of 0 no turn can move a parameter: the fine-tuned bank (kept, as
    # before = -1 is below anything) is the levels' bank, while the levels did learn
    levels_banks = _record_levels_bank(monkeypatch, -1.0)
    cfg = TrainConfig(**(SMALL | {"finetune_threshold": 1.0,
                                  "finetune_agent": {"learning_rate": 0.0}}))
    res = run(make_keydoor(), cfg, [0], progress=False)
    assert res["finetune"]["kept"] == ["fine-tuned"] and res["finetune"]["episodes"][0] > 0
    assert _banks_equal(res["_raw"]["bank"], levels_banks[0])
    with pytest.raises(ConfigError, match="finetune_agent.*'lr'.*learning_rate"):
        run(make_keydoor(), TrainConfig(**(SMALL | {"finetune_agent": {"lr": 1e-3}})), [0],
            progress=False)
    with pytest.raises(ConfigError, match="finetune_agent"):
        TrainConfig(finetune_agent={"learning_rate": "fast"})


def test_without_finetuning_the_counts_are_the_levels():
    cfg = TrainConfig(**(SMALL | {"finetune": "off"}))
    res = run(make_keydoor(), cfg, [0], progress=False)
    assert res["finetune"] is None
    assert res["total_episodes"] == [sum(rec["episodes"][0] for rec in res["levels"])]


def _in_a_second_turn(trainer) -> bool:
    return any(trainer.finetuning(s) and trainer.state.finetune[s].turn >= 1
               for s in range(len(trainer.seeds)))


def test_resume_during_finetuning_is_exact(tmp_path, monkeypatch):
    # checkpoints at level and turn boundaries only (a save per chunk is slow), every one
    # written at once (not coalesced with the next), so a turn's start is checkpointed
    cfg = TrainConfig(**(SMALL | {"checkpoint_every": 1e9}))
    straight = run(make_keydoor(), cfg, [0, 1], tmp_path / "straight", progress=False)
    monkeypatch.setattr(CheckpointHook, "STAGE_GAP_WRITES", 0)
    lose_machine_after_save(monkeypatch, _in_a_second_turn)
    out = tmp_path / "moved"
    with pytest.raises(MachineLost):
        run(make_keydoor(), cfg, [0, 1], out, progress=False)
    monkeypatch.undo()
    host = ckpt.load_meta(out)["meta"]["host"]
    assert any(t >= 1 for t in host["finetune"]["turn"])
    assert any(stage == 2 for stage in host["stage"])  # 2 levels, then fine-tuning
    # the same checkpoint marked as of an older format is refused, naming both formats,
    # before the trainer is built; this one resumes exactly, its levels' bank included
    old = tmp_path / "format4"
    shutil.copytree(out, old)
    with_format(old, 4)
    with pytest.raises(ckpt.CheckpointError, match="of format 4.*resumes format 5 only"):
        run(make_keydoor(), cfg, [0, 1], old, progress=False, resume=True)
    resumed = run(make_keydoor(), cfg, [0, 1], out, progress=False, resume=True)
    assert _strip_timing(resumed) == _strip_timing(straight)
    assert resumed["finetune"]["baseline"] == [True, True]


@pytest.mark.parametrize("go_on", [True, False])
def test_a_new_turn_goes_on_with_the_episodes_in_flight(monkeypatch, go_on):
    # a later turn hands the same episodes to its learner (the old learner's pending
    # decision and episode record cleared); off, every turn starts fresh episodes
    from smjax.train.loop import HierarchyTrainer
    start, seen = HierarchyTrainer.start, []

    def spy(self, seeds, **rehearse):
        later = [s for s in seeds if self.finetuning(s) and self.state.finetune[s].turns]
        before = jax.tree.map(np.asarray, self.arrays.state.carry)
        start(self, seeds, **rehearse)
        if later:
            seen.append((later, before, jax.tree.map(np.asarray, self.arrays.state.carry)))

    monkeypatch.setattr(HierarchyTrainer, "start", spy)
    cfg = TrainConfig(**(SMALL | {"finetune_threshold": 1.0, "finetune_max_episodes": 300,
                                  "finetune_continue_episodes": go_on}))
    run(make_keydoor(), cfg, [0, 1], progress=False)
    assert seen
    for later, before, after in seen:
        for s in later:
            kept = [np.array_equal(b[s], a[s]) for b, a in zip(
                jax.tree.leaves((before.env_state, before.obs, before.stack, before.task_return)),
                jax.tree.leaves((after.env_state, after.obs, after.stack, after.task_return)))]
            assert all(kept) if go_on else not all(kept)
            assert not after.learner_started[s].any() and not after.learner_return[s].any()
            assert not after.pending.decision[s].any()
    with pytest.raises(ConfigError, match="finetune_continue_episodes"):
        TrainConfig(finetune_continue_episodes="yes")


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(0, 4), st.data())
def test_converged_options_rest_at_most_max_rest_turns_in_a_row(num_options, max_rest, data):
    from smjax.train.finetune_ops import next_turn

    order = [f"o{i}" for i in range(num_options)]
    success = st.one_of(st.none(), st.floats(0, 1))
    turns, rested, turn = [], {}, 0  # turn 0 (o0) is playing
    played, skipped_in_a_row = [0], {name: 0 for name in order}
    for _ in range(30):
        turns.append({"template": order[turn % num_options], "episodes": 1,
                      "running_success": data.draw(success)})
        new = next_turn(turn, order, turns, rested, 0.95, max_rest)
        assert new > turn
        last = {t["template"]: t["running_success"] for t in turns}
        for skipped in range(turn + 1, new):  # passed over: converged, and within its rests
            name = order[skipped % num_options]
            assert last.get(name) is not None and last[name] >= 0.95
            skipped_in_a_row[name] += 1
            assert skipped_in_a_row[name] <= max_rest
        name = order[new % num_options]
        skipped_in_a_row[name] = 0
        assert rested[name] == 0
        turn = new
        played.append(turn)
    if max_rest == 0:  # every option plays every round
        assert played == list(range(31))


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 4), st.integers(2, 5), st.data())
def test_a_turn_writes_only_its_own_option_of_its_own_seed(num_seeds, num_options, data):
    mask = np.array(data.draw(st.lists(st.booleans(), min_size=num_seeds, max_size=num_seeds)))
    options = np.array(data.draw(st.lists(st.integers(0, num_options - 1), min_size=num_seeds,
                                          max_size=num_seeds)), np.int32)
    bank = {"w": jnp.arange(num_seeds * num_options * 3, dtype=jnp.float32)
            .reshape(num_seeds, num_options, 3)}
    params = {"w": -jnp.ones((num_seeds, 3))}
    learned = jnp.zeros((num_seeds, num_options), bool)
    new_bank, new_learned = freeze(jnp.asarray(mask), jnp.asarray(options), params, bank, learned)
    changed = np.asarray((new_bank["w"] != bank["w"]).any(-1))
    expected = np.zeros((num_seeds, num_options), bool)
    expected[np.arange(num_seeds), options] = mask
    np.testing.assert_array_equal(changed, expected)
    np.testing.assert_array_equal(np.asarray(new_learned), expected)


@pytest.mark.parametrize("algo", ["ppo", "dqn", "actor-critic"])
def test_warm_start_continues_from_the_trained_params(algo):
    agent = make_agent(algo)
    obs = jnp.zeros((5,))
    fresh = agent.init(jax.random.PRNGKey(0), obs, 3)
    trained = agent.init(jax.random.PRNGKey(1), obs, 3).params
    warm = agent.warm_start(fresh, trained)
    same = jax.tree.map(lambda a, b: bool((a == b).all()), warm.params, trained)
    assert all(jax.tree.leaves(same))
    if algo == "dqn":  # the target net starts equal to the trained one
        assert all(jax.tree.leaves(jax.tree.map(lambda a, b: bool((a == b).all()),
                                                warm.target_params, trained)))
    # exploration starts where its schedule ended (ppo has none: it samples its policy)
    if algo == "dqn":  # epsilon 0.05: the greedy action almost always
        batch = jnp.zeros((256, 5))
        acts = agent.act(warm, batch, jnp.ones((256, 3), bool), jax.random.PRNGKey(2)).action
        greedy = jnp.argmax(agent.policy_logits(trained, batch), -1)
        assert float((acts == greedy).mean()) > 0.9
    if algo == "actor-critic":
        from smjax.agents.actor_critic import ActorCriticConfig, exploration_epsilon

        assert float(exploration_epsilon(ActorCriticConfig(), warm.episodes_seen)) < 1e-6
