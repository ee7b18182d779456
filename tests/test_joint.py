"""Joint fine-tuning: every learned option learns at once, each from its own record."""
import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

from _helpers import MachineLost, lose_machine_after_save
from hier_env import make_keydoor
from smjax.agents import make_agent
from smjax.core.transition import ActOutput, Transition
from smjax.options import joint
from smjax.options.carry import NO_OPTION, Controls
from smjax.train import ConfigError, TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.engine import Engine
from smjax.train.learner import make_joint_learner
from smjax.train.loop import HierarchyTrainer
from smjax.train.plans import plan_levels
from smjax.train.run import run
from smjax.train.state import FinetuneCounters, SuccessWindow
from test_finetune import CFG, SMALL, FarTeleport, _strip_timing, assert_the_teleport_fixed

JOINT = CFG | {"finetune_mode": "joint"}
JOINT_SMALL = SMALL | {"finetune_mode": "joint"}


@pytest.fixture(scope="module")
def far_teleport_joint():
    env = FarTeleport()
    return run((env, env.default_params), TrainConfig(**JOINT), [0, 1], progress=False)


def test_joint_finetuning_fixes_what_the_teleport_hid(far_teleport_joint):
    assert_the_teleport_fixed(far_teleport_joint)


def test_joint_results_keep_the_contract(far_teleport_joint):
    ft = far_teleport_joint["finetune"]
    assert ft["mode"] == "joint"
    for s in range(2):
        assert [t["template"] for t in ft["turns"][s]] == ["joint"]  # no turns: one phase
        assert ft["stop"][s] in ("gate", "plateau", "budget")
        assert (ft["stop"][s] == "gate") == ft["reached"][s]
        levels = sum(rec["episodes"][s] for rec in far_teleport_joint["levels"])
        assert far_teleport_joint["total_episodes"][s] == levels + ft["episodes"][s]


def _record(T=6, B=5, O=3, A=4, seed=0):
    """A random joint record [T, B, O] (obs shared), as a rollout's scan stacks it."""
    k = jax.random.split(jax.random.PRNGKey(seed), 8)
    return Transition(
        obs=jax.random.normal(k[0], (T, B, 5)),
        action=jax.random.randint(k[1], (T, B, O), 0, A),
        action_mask=jnp.ones((T, B, O, A), bool),
        log_prob=jnp.full((T, B, O), -np.log(A), jnp.float32),
        value=jax.random.normal(k[2], (T, B, O)),
        decision=jax.random.bernoulli(k[3], 0.5, (T, B, O)),
        reward=jax.random.uniform(k[4], (T, B, O)),
        discount=jnp.full((T, B, O), 0.99, jnp.float32),
        done=jax.random.bernoulli(k[5], 0.2, (T, B, O)))


@pytest.fixture(scope="module")
def keydoor_engine():
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    engine = Engine(env, params, h, make_agent("ppo"), TrainConfig(**JOINT_SMALL))
    return engine, _joint_state(engine), jax.jit(engine._learn_joint)


def _joint_state(engine):
    """A fresh joint state for one seed (``joint_chunk`` consumes the one it is given)."""
    return engine.joint_state(engine.init_learner(jax.random.PRNGKey(1)[None]),
                              engine.new_bank(engine.init_learner(jax.random.PRNGKey(2)[None])),
                              jax.random.PRNGKey(3)[None], jax.random.PRNGKey(4)[None])


def _update_inputs(engine, state, seed: int = 0):
    """One seed's learners, its carry (only the pending rows of 5 environments are read)
    and a random joint record [6, 5, O] over random observations."""
    O, B, A = engine.h.num_options, 5, engine.h.num_actions
    learners = jax.tree.map(lambda x: x[0], state.learner)
    obs = jax.random.normal(jax.random.PRNGKey(5), (6, B) + engine.example_obs.shape)
    traj = _record(B=B, O=O, A=A, seed=seed)._replace(obs=obs)
    pending = jax.tree.map(lambda x: x[0, :, :B], state.carry.pending)
    return learners, state.carry.replace(pending=pending), traj


@settings(max_examples=6, deadline=None, phases=[Phase.generate])
@given(data=st.data(), seed=st.integers(0, 2**16))
def test_each_option_trains_only_on_its_own_rows(keydoor_engine, data, seed):
    # scrambling one option's columns of the record (its decisions, actions, rewards,
    # discounts, ends) leaves every other option's update exactly as it was
    engine, state, learn = keydoor_engine
    O, B, A = engine.h.num_options, 5, engine.h.num_actions
    other = data.draw(st.integers(0, O - 1))
    learners, carry, traj = _update_inputs(engine, state, seed)
    scrambled = _record(B=B, O=O, A=A, seed=seed + 1)
    pick = lambda a, b: a.at[:, :, other].set(b[:, :, other])  # noqa: E731
    scrambled = scrambled._replace(discount=jax.random.uniform(jax.random.PRNGKey(seed),
                                                               scrambled.discount.shape))
    changed = traj._replace(**{f: pick(getattr(traj, f), getattr(scrambled, f))
                               for f in ("action", "log_prob", "value", "decision", "reward",
                                         "discount", "done")})
    key = jax.random.PRNGKey(7)
    first, _, _ = learn(learners, carry, traj, key)
    second, _, _ = learn(learners, carry, changed, key)
    for o in set(range(O)) - {other}:
        assert all(jax.tree.leaves(jax.tree.map(lambda a, b: bool((a[o] == b[o]).all()),
                                                first.params, second.params))), o
    moved = jax.tree.leaves(jax.tree.map(lambda a, b: bool((a[other] != b[other]).any()),
                                         first.params, second.params))
    assert any(moved)  # (the scrambled option did train on its new rows)


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_an_options_record_is_its_own(data):
    B, O, A = data.draw(st.integers(1, 4)), data.draw(st.integers(1, 5)), 3
    flags = lambda: np.array(data.draw(st.lists(st.booleans(), min_size=B * O,  # noqa: E731
                                                max_size=B * O))).reshape(B, O)
    on, after, sat, chose = flags(), flags(), flags(), flags()
    after &= on  # nothing is pushed by the pops
    reset = np.array(data.draw(st.lists(st.booleans(), min_size=B, max_size=B)))
    learned = np.array(data.draw(st.lists(st.booleans(), min_size=O, max_size=O)))
    reward = np.arange(B, dtype=np.float32) + 0.5
    r = np.asarray(joint.option_rewards(jnp.asarray(reward), jnp.asarray(sat), jnp.asarray(on)))
    np.testing.assert_array_equal(r[:, 0], reward)  # the root: the environment's reward
    np.testing.assert_array_equal(r[:, 1:], (on & sat)[:, 1:])  # a template: its F_o, on
    done = np.asarray(joint.option_ends(jnp.asarray(on), jnp.asarray(after), jnp.asarray(reset)))
    np.testing.assert_array_equal(done, (on & ~after) | reset[:, None])
    acts = ActOutput(jnp.zeros((O, B), jnp.int32), jnp.zeros((O, B)), jnp.zeros((O, B)))
    tr = joint.option_transitions(jnp.zeros((B, 2)), acts, jnp.ones((B, O, A), bool),
                                  jnp.asarray(chose), jnp.asarray(learned), jnp.asarray(r),
                                  jnp.ones((B, O)), jnp.asarray(done))
    # an option's decisions are its own choices, and only a learned option's
    np.testing.assert_array_equal(np.asarray(tr.decision), chose & learned[None, :])


def test_a_joint_rollout_records_every_learned_option(keydoor_engine):
    # every learned option decides in some ticks; the record's rows have the per-option
    # layout OPTION_AXES maps over
    engine, state, _ = keydoor_engine
    O = engine.h.num_options
    learned = jnp.ones((1, O), bool)
    sizes = jnp.asarray([[32, 32]], jnp.int32)
    windows = (SuccessWindow.empty(1, 32), SuccessWindow.empty(1, 32))
    new, _, metrics, _, _, finite = engine.joint_chunk(
        state, jnp.ones((1,), bool), learned, jnp.ones((1,), jnp.float32),
        jnp.full((1, O), 0.99, jnp.float32), windows, sizes)
    decisions = np.asarray(metrics["decisions"])  # [1, U, O]
    assert decisions.shape == (1, SMALL["updates_per_chunk"], O)
    assert (decisions.sum(1) > 0).all(), decisions  # every option learned from something
    assert jax.tree.leaves(new.learner)[0].shape[:2] == (1, O)
    assert bool(finite.all())


def test_each_option_is_discounted_at_its_own_gamma(keydoor_engine):
    # the joint record's discount is per option: with no teleports in fine-tuning, each
    # tick's is exactly that option's gamma (a root at 0.99 above options at 0.9 keeps
    # both horizons, rather than re-fitting the options at the root's)
    engine, _, _ = keydoor_engine
    state = _joint_state(engine)
    O = engine.h.num_options
    gamma = jnp.linspace(0.99, 0.9, O).astype(jnp.float32)
    controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0, jnp.int32), jnp.ones((O,), bool),
                        gamma=gamma, teleport=jnp.asarray(False),
                        continue_episodes=jnp.asarray(False), temperature=engine.temperature,
                        side_cost=jnp.asarray(1.0), acts_frozen=True, joint=True)
    learners = jax.tree.map(lambda x: x[0], state.learner)
    carry = jax.tree.map(lambda x: x[0], state.carry)
    tick = jax.jit(lambda c, k: engine.runner.tick(c, k, learners, None, controls))
    for t in range(3):
        carry, record, _ = tick(carry, jax.random.PRNGKey(t))
        chex.assert_shape(record.discount, (carry.obs.shape[0], O))
        np.testing.assert_allclose(np.asarray(record.discount),
                                   np.broadcast_to(np.asarray(gamma), record.discount.shape))


def test_joint_finetuning_keeps_each_levels_discount():
    # TrainConfig.levels' per-level gamma reaches each option in joint fine-tuning (it
    # used to be the root level's for every option)
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    root, *below = plan_levels(h, "top-down")
    cfg = TrainConfig(**JOINT_SMALL | {"gamma": 0.95, "levels": {root.name: {"gamma": 0.99},
                                                                 below[0].name: {"gamma": 0.5}}})
    trainer = HierarchyTrainer(Engine(env, params, h, make_agent("ppo"), cfg),
                               plan_levels(h, "top-down"), [0], progress=False)
    want = [0.95] * h.num_options
    want[root.option], want[below[0].option] = 0.99, 0.5
    assert trainer.finetune.option_gammas(0) == want


def _in_the_joint_phase(trainer) -> bool:
    return any(trainer.finetuning(s) and trainer.state.finetune[s].episodes > 0
               for s in range(len(trainer.seeds)))


def test_resume_during_joint_finetuning_is_exact(tmp_path, monkeypatch):
    from smjax.train.hooks import CheckpointHook

    cfg = TrainConfig(**(JOINT_SMALL | {"checkpoint_every": 1e9, "finetune_threshold": 1.0,
                                        "finetune_max_episodes": 96}))
    straight = run(make_keydoor(), cfg, [0, 1], progress=False)
    # saves at level ends, then once inside the joint phase (there it has no boundary of
    # its own), where the machine is lost
    def save_in_the_joint_phase(hook, trainer, report):
        if report.stage_ended or _in_the_joint_phase(trainer):
            hook.save(trainer)

    monkeypatch.setattr(CheckpointHook, "chunk", save_in_the_joint_phase)
    lose_machine_after_save(monkeypatch, _in_the_joint_phase)
    out = tmp_path / "moved"
    with pytest.raises(MachineLost):
        run(make_keydoor(), cfg, [0, 1], out, progress=False)
    monkeypatch.undo()
    assert any(ckpt.load_meta(out)["meta"]["host"]["finetune"]["episodes"])
    resumed = run(make_keydoor(), cfg, [0, 1], out, progress=False, resume=True)
    assert _strip_timing(resumed) == _strip_timing(straight)


@pytest.mark.parametrize("algo", ["dqn", "actor-critic"])
def test_joint_finetuning_runs_every_learner(algo):
    cfg = TrainConfig(**(JOINT_SMALL | {"algo": algo, "finetune_threshold": 1.0}))
    res = run(make_keydoor(), cfg, [0], progress=False)
    assert res["finetune"]["episodes"][0] > 0 and np.isfinite(res["final_success"]).all()


def test_the_phase_stops_on_a_plateau():
    counters = FinetuneCounters()
    for success in (30.0, 40.0, 40.5):  # blocks of 50 episodes: 0.6, 0.8, 0.81
        counters.add_to_block(success, 50, 50)
        assert counters.block_episodes == 0
    assert counters.block_means == [0.6, 0.8, 0.81]
    assert counters.plateaued(0.02) and not counters.plateaued(0.005)
    counters.add_to_block(10.0, 20, 50)  # a block in progress closes nothing
    assert counters.block_means == [0.6, 0.8, 0.81] and counters.block_episodes == 20
    # in a run: a gain no block can show ends the phase after its second block
    cfg = TrainConfig(**(JOINT_SMALL | {"finetune_threshold": 1.0, "finetune_max_episodes": 5000,
                                        "finetune_plateau_episodes": 60,
                                        "finetune_plateau_gain": 1.0}))
    ft = run(make_keydoor(), cfg, [0], progress=False)["finetune"]
    assert ft["stop"] == ["plateau"] and len(ft["block_means"][0]) == 2
    assert 120 <= ft["episodes"][0] < 5000


def test_a_hierarchy_that_passes_before_the_phase_is_not_fine_tuned(monkeypatch):
    # the evaluation before the phase is its first gate: at a threshold the levels'
    # hierarchy already passes (KeyDoor's SMALL levels leave it at ~0.3-0.4), no episode is
    # fine-tuned and the levels' bank is handed back untouched
    from smjax.train.finetune import FinetuneStage

    banks, real = [], FinetuneStage.enter

    def enter(self, st, seeds):  # and keep the bank as the levels left it
        real(self, st, seeds)
        if seeds:
            banks.append(jax.tree.map(np.asarray, self.slots.arrays.bank))

    monkeypatch.setattr(FinetuneStage, "enter", enter)
    res = run(make_keydoor(), TrainConfig(**(JOINT_SMALL | {"finetune_threshold": 0.05})),
              [0, 1], progress=False)
    ft = res["finetune"]
    assert ft["episodes"] == [0, 0] and ft["env_steps"] == [0, 0] and ft["turns"] == [[], []]
    assert ft["stop"] == ["gate"] * 2 and ft["reached"] == [True] * 2
    assert ft["kept"] == ["levels"] * 2 and ft["gate_attempts"] == [1, 1]
    assert ft["gate_success"] == ft["final_success_before"]
    assert min(ft["final_success_before"]) >= 0.05 and min(ft["gate_env_steps"]) > 0
    levels = [sum(rec["episodes"][s] for rec in res["levels"]) for s in range(2)]
    assert res["total_episodes"] == levels
    # (the seeds may end their levels in different chunks: the last bank holds both)
    assert banks and all(jax.tree.leaves(jax.tree.map(
        lambda x, y: bool((np.asarray(x) == y).all()), res["_raw"]["bank"], banks[-1])))


def test_bad_joint_settings_are_refused():
    for field, value in (("finetune_mode", "both"), ("finetune_plateau_episodes", -1),
                         ("finetune_plateau_episodes", 2.5), ("finetune_plateau_gain", 1.5)):
        with pytest.raises(ConfigError, match=field):
            TrainConfig(**{field: value})
    cfg = TrainConfig(**(JOINT_SMALL | {"agent": {"recurrent_size": 8}}))
    with pytest.raises(ConfigError, match="recurrent"):
        run(make_keydoor(), cfg, [0], progress=False)


def _grad_steps_of_one_update(engine, state):
    """Each option's gradient steps in one joint update of a random record in which every
    option decides at every tick."""
    learners, carry, traj = _update_inputs(engine, state)
    traj = traj._replace(decision=jnp.ones_like(traj.decision))
    after, _, _ = jax.jit(engine._learn_joint)(learners, carry, traj, jax.random.PRNGKey(7))
    return np.asarray(after.grad_steps - learners.grad_steps)


def test_finetune_agent_sets_the_joint_updates_epochs_and_minibatches():
    # the levels' learner takes 4 epochs x 4 minibatches of steps, joint fine-tuning's
    # (finetune_agent) 1 x 2: the same learners, updated by another update
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    cfg = TrainConfig(**(JOINT_SMALL | {"finetune_agent": {"update_epochs": 1,
                                                           "num_minibatches": 2}}))
    levels_agent = make_agent("ppo")
    joint_agent = make_joint_learner(env, params, cfg, levels_agent)
    assert joint_agent is not levels_agent
    assert make_joint_learner(env, params, TrainConfig(**JOINT_SMALL), levels_agent) \
        is levels_agent
    engine = Engine(env, params, h, levels_agent, cfg, joint_agent)
    default = Engine(env, params, h, levels_agent, TrainConfig(**JOINT_SMALL))
    assert (_grad_steps_of_one_update(engine, _joint_state(engine)) == 2).all()
    assert (_grad_steps_of_one_update(default, _joint_state(default)) == 16).all()


def test_a_run_fine_tunes_with_the_joint_learner(monkeypatch):
    import sys

    import smjax.train.engine as engine_module

    run_module = sys.modules["smjax.train.run"]  # (``smjax.train.run`` is also the function)

    made, used = [], []
    real_make, real_update = run_module.make_joint_learner, engine_module.options_update
    monkeypatch.setattr(run_module, "make_joint_learner",
                        lambda *a: made.append(real_make(*a)) or made[-1])
    monkeypatch.setattr(engine_module, "options_update",
                        lambda agent: used.append(agent) or real_update(agent))
    cfg = TrainConfig(**(JOINT_SMALL | {"finetune_threshold": 1.0,
                                        "finetune_agent": {"update_epochs": 1}}))
    res = run(make_keydoor(), cfg, [0], progress=False)
    assert res["finetune"]["episodes"][0] > 0
    assert used and all(agent is made[0] for agent in used)


def test_finetune_agent_update_settings_are_checked():
    tuned = {"finetune_agent": {"update_epochs": 1}}
    with pytest.raises(ConfigError, match="only joint fine-tuning.*--finetune-mode joint"):
        run(make_keydoor(), TrainConfig(**(SMALL | tuned)), [0], progress=False)
    with pytest.raises(ConfigError, match="finetune_agent.*update_epochs"):
        TrainConfig(**(JOINT_SMALL | {"finetune_agent": {"update_epochs": 0}}))
    # a setting that changes the learner's parameters would not fit the levels' learners
    cfg = TrainConfig(**(JOINT_SMALL | {"finetune_agent": {"recurrent_size": 8}}))
    with pytest.raises(ConfigError, match="changes the learner's state"):
        run(make_keydoor(), cfg, [0], progress=False)
