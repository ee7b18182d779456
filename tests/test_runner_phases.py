"""The tick's phases one at a time (smjax.options.phases / realise), on hand-built
situations whose outcome can be stated: decide (who picks, what is pushed, teleported or
scripted), pop (exactly the ended levels go, stack invariants hold), account (rewards,
returns, episode ends, SMDP discounts), realise (families), step; and evaluation
without a learner state."""
import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hier_env import KeyDoor
from smjax.options import Parametric
from smjax.options import phases
from smjax.options.carry import NO_OPTION
from smjax.options.realise import families, primitive_action, run_family
from smjax.options.runner import Controls, HierarchyRunner
from smjax.options.stack import EMPTY, ExecutionStack, stack_init, stack_push

P = 3  # primitives 0..2; option o (>= 1) is action P + o - 1
O = 4  # options: root 0, templates 1..3
D = 4  # stack capacity


def act_of(option: int) -> int:
    return P + option - 1


def stack_of(*options: int, steps=None, capacity: int = D) -> ExecutionStack:
    s = stack_init(capacity, options[0])
    for o in options[1:]:
        s = stack_push(s, o)
    if steps is not None:
        s = s.replace(steps=jnp.asarray(list(steps) + [0] * (capacity - len(steps)), jnp.int32))
    return s


def batch(*stacks: ExecutionStack) -> ExecutionStack:
    return jax.tree.map(lambda *xs: jnp.stack(xs), *stacks)


def run_decide(stack, frozen, learner_choice, *, learner=NO_OPTION, learned=(True, False, False, False),
               pushable=(True, True, True, True), callable_=(True, True, True, True)):
    return phases.decide(stack, jnp.asarray(frozen, jnp.int32), jnp.asarray(learner_choice, jnp.int32),
                         learner=jnp.asarray(learner), learned=jnp.asarray(learned),
                         pushable=jnp.asarray(pushable), callable_=jnp.asarray(callable_),
                         num_primitives=P)


# ---- decide -------------------------------------------------------------------------
def test_learned_root_takes_its_frozen_primitive():
    d = run_decide(stack_of(0), [1, 0, 0, 0], 2)
    assert int(d.primitive) == 1 and int(d.teleported) == NO_OPTION and int(d.scripted) == NO_OPTION
    assert int(d.stack.depth) == 1 and not bool(d.learner_decided)


def test_frozen_call_is_pushed_and_the_learner_below_it_decides():
    # the learned root calls template 2, which is the learner; the learner takes primitive 2
    d = run_decide(stack_of(0), [act_of(2), 0, 0, 0], 2, learner=2)
    assert int(d.stack.depth) == 2 and int(d.stack.option[1]) == 2
    assert int(d.primitive) == 2 and bool(d.learner_decided)


def test_a_chain_of_learned_calls_walks_down_to_a_primitive():
    learned = (True, True, True, False)
    d = run_decide(stack_of(0), [act_of(1), act_of(2), 0, 0], 1, learned=learned)
    np.testing.assert_array_equal(np.asarray(d.stack.option), [0, 1, 2, EMPTY])
    assert int(d.primitive) == 0 and not bool(d.learner_decided)


def test_unlearned_option_on_the_stack_plays_its_script():
    d = run_decide(stack_of(0, 3), [act_of(1), 0, 0, 2], 1)
    assert int(d.scripted) == 3 and int(d.teleported) == NO_OPTION
    assert int(d.stack.depth) == 2  # the root does not choose again while its callee runs


def test_a_call_that_cannot_be_pushed_is_teleported():
    d = run_decide(stack_of(0), [act_of(3), 0, 0, 0], 0, pushable=(True, True, True, False))
    assert int(d.teleported) == 3 and int(d.stack.depth) == 1 and int(d.scripted) == NO_OPTION


def test_the_learner_at_the_root_decides_and_its_teleport_counts_as_its_choice():
    d = run_decide(stack_of(0), [0, 0, 0, 0], act_of(1), learner=0,
                   learned=(False, False, False, False), pushable=(True, False, False, False))
    assert bool(d.learner_decided) and int(d.teleported) == 1


def test_pushable_options():
    got = phases.pushable_options(
        jnp.asarray([True, False, False, False]), jnp.asarray(2),
        jnp.asarray([False, True, False, True]), jnp.asarray([False, True, False, False]),
        jnp.asarray(True))
    # 0 learned, 2 the learner, 3 scripted; 1 scripted but teleported while teleports are on
    np.testing.assert_array_equal(np.asarray(got), [True, False, True, True])


@settings(max_examples=25, deadline=None)
@given(depth=st.integers(1, D), choices=st.lists(st.integers(0, P + O - 2), min_size=O, max_size=O),
       learned=st.lists(st.booleans(), min_size=O, max_size=O),
       pushable=st.lists(st.booleans(), min_size=O, max_size=O), learner=st.integers(-1, O - 1))
def test_decide_keeps_the_stack_below_and_fixes_at_most_one_realisation(
        depth, choices, learned, pushable, learner):
    stack = stack_of(*([0] + [1 + i % (O - 1) for i in range(depth - 1)]))
    d = run_decide(stack, choices, choices[0], learner=learner, learned=learned, pushable=pushable)
    new_depth = int(d.stack.depth)
    assert depth <= new_depth <= D
    np.testing.assert_array_equal(np.asarray(d.stack.option[:depth]), np.asarray(stack.option[:depth]))
    for o in np.asarray(d.stack.option[depth:new_depth]):  # only pushable options are pushed
        assert pushable[o]
    assert not (int(d.teleported) >= 0 and int(d.scripted) >= 0)
    if int(d.teleported) >= 0:
        assert not pushable[int(d.teleported)]


def test_a_vmapped_walk_writes_without_scatters():
    """The walk's pushes and its record of who chose are masked writes: vmapped over the
    environments, an indexed write would be a scatter, on a GPU a kernel and a copy of the
    stack of its own at every step of every tick."""
    stacks = batch(stack_of(0), stack_of(0, 1), stack_of(0, 1, 2))
    frozen = jnp.asarray([[act_of(1), act_of(2), act_of(3), 0]] * 3, jnp.int32)
    walk = jax.vmap(lambda st, f: run_decide(st, f, 0, learned=(True, True, True, False)))
    text = jax.jit(walk).lower(stacks, frozen).as_text()
    assert "scatter" not in text
    d = walk(stacks, frozen)  # and the walk still pushes down to the unlearned template
    np.testing.assert_array_equal(d.stack.depth, [4, 4, 4])
    np.testing.assert_array_equal(d.scripted, [3, 3, 3])


# ---- pop ----------------------------------------------------------------------------
K_MAX = jnp.asarray([10 ** 6, 5, 5, 3], jnp.int32)


def test_pop_ends_the_lowest_stopped_level_and_everything_above():
    stack = batch(stack_of(0, 1, 2), stack_of(0, 1, 2), stack_of(0, 1, 2))
    stop = jnp.asarray([[False, True, False, False], [False, False, False, False],
                        [False, False, True, False]])
    popped = phases.pop(stack, stop, K_MAX, jnp.asarray(2))
    chex.assert_shape(popped.first_end, (3,))
    np.testing.assert_array_equal(np.asarray(popped.stack.depth), [1, 3, 2])
    np.testing.assert_array_equal(np.asarray(popped.stack.option),
                                  [[0, -1, -1, -1], [0, 1, 2, -1], [0, 1, -1, -1]])
    np.testing.assert_array_equal(np.asarray(popped.stack.steps),
                                  [[1, 0, 0, 0], [1, 1, 1, 0], [1, 1, 0, 0]])
    np.testing.assert_array_equal(np.asarray(popped.first_end), [1, D, 2])
    np.testing.assert_array_equal(np.asarray(popped.learner_on), [True, True, True])
    # the learner (option 2) ends with its caller (row 0) and by itself (row 2)
    np.testing.assert_array_equal(np.asarray(popped.learner_ended), [True, False, True])


def test_pop_ends_a_level_out_of_ticks_and_keeps_its_caller():
    stack = batch(stack_of(0, 3, steps=[7, 2]))  # option 3 has k_max 3: this is its third tick
    popped = phases.pop(stack, jnp.zeros((1, O), bool), K_MAX, jnp.asarray(0))
    assert int(popped.stack.depth[0]) == 1 and int(popped.first_end[0]) == 1
    assert bool(popped.learner_on[0]) and not bool(popped.learner_ended[0])


def test_a_satisfied_option_that_is_not_on_the_stack_pops_nothing():
    popped = phases.pop(batch(stack_of(0, 1)), jnp.asarray([[False, False, True, True]]), K_MAX,
                        jnp.asarray(NO_OPTION))
    assert int(popped.stack.depth[0]) == 2 and not bool(popped.learner_on[0])


@settings(max_examples=30, deadline=None)
@given(options=st.lists(st.integers(1, O - 1), min_size=0, max_size=D - 1),
       steps=st.lists(st.integers(0, 6), min_size=D, max_size=D),
       stop=st.lists(st.booleans(), min_size=O, max_size=O), learner=st.integers(-1, O - 1))
def test_pop_invariants(options, steps, stop, learner):
    depth = len(options) + 1
    stack = stack_of(0, *options, steps=steps[:depth])
    popped = phases.pop(batch(stack), jnp.asarray([stop]), K_MAX, jnp.asarray(learner))
    out = jax.tree.map(lambda x: np.asarray(x[0]), popped.stack)
    ids = [0] + options
    ends = [stop[o] or steps[i] + 1 >= int(K_MAX[o]) for i, o in enumerate(ids)]
    expected = ends.index(True) if any(ends) else depth
    assert int(out.depth) == expected
    np.testing.assert_array_equal(out.option[:expected], ids[:expected])
    np.testing.assert_array_equal(out.steps[:expected], np.asarray(steps[:expected]) + 1)
    assert (out.option[expected:] == EMPTY).all() and (out.steps[expected:] == 0).all()
    # the learner's run ends where its own entry (its lowest, if called twice) or one below ends
    on = learner in ids
    assert bool(popped.learner_on[0]) == on
    assert bool(popped.learner_ended[0]) == (on and expected <= ids.index(learner))


# ---- account ------------------------------------------------------------------------
GAMMA = 0.9


def test_tick_discount_is_gamma_or_gamma_to_the_nominal_duration():
    nominal = jnp.asarray([1.0, 4.0, 2.0])
    got = phases.tick_discount(jnp.asarray([NO_OPTION, 1, 2]), nominal, GAMMA)
    np.testing.assert_allclose(np.asarray(got), [GAMMA, GAMMA ** 4, GAMMA ** 2], rtol=1e-6)


def _popped(first_end, learner_on, learner_ended):
    first_end = jnp.asarray(first_end, jnp.int32)
    return phases.Popped(None, first_end, jnp.asarray(learner_on), jnp.asarray(learner_ended))


def _account(carry, *, decided, reward, env_done, popped, satisfied=False, learner=0, start=0,
             reset_on_learner_end=True, info_success=None, shaping=0.0):
    started, ret, task_ret = carry
    return phases.account(
        started=started, learner_return=ret, task_return=task_ret,
        decided=jnp.asarray(decided), reward=jnp.asarray(reward, jnp.float32),
        env_done=jnp.asarray(env_done), popped=popped,
        learner_satisfied=jnp.asarray(satisfied), shaping=shaping, info_success=info_success,
        learner=jnp.asarray(learner), start=jnp.asarray(start),
        reset_on_learner_end=reset_on_learner_end)


def test_root_learner_returns_sum_the_environment_rewards_of_its_episode():
    carry = (jnp.zeros(1, bool), jnp.zeros(1), jnp.zeros(1))
    rewards, dones = [0.0, 0.5, 1.0], [False, False, True]
    for r, done in zip(rewards, dones):
        acc = _account(carry, decided=[r == 0.0], reward=[r], env_done=[done],
                       popped=_popped([D], [True], [False]))
        carry = (acc.started, acc.learner_return, acc.task_return)
    assert bool(acc.reset[0]) and bool(acc.learner_done[0]) and bool(acc.ends.finished[0])
    np.testing.assert_allclose(float(acc.ends.ret[0]), 1.5)
    np.testing.assert_allclose(float(acc.ends.task_success[0]), 1.5)  # no info["success"]
    assert float(carry[1][0]) == 0.0 and float(carry[2][0]) == 0.0 and not bool(carry[0][0])


def test_smdp_return_of_a_run_of_rewards_is_the_gamma_weighted_sum():
    """What a learner makes of the recorded rewards and discounts: an option that runs k
    ticks earns sum_i gamma^i r_i (the discounts multiply tick by tick, a teleport
    counting its nominal duration)."""
    teleported = jnp.asarray([1, NO_OPTION, NO_OPTION])
    discounts = phases.tick_discount(teleported, jnp.asarray([1.0, 3.0]), GAMMA)
    rewards = jnp.asarray([1.0, 2.0, 4.0])
    weights = jnp.concatenate([jnp.ones(1), jnp.cumprod(discounts)[:-1]])
    np.testing.assert_allclose(float((weights * rewards).sum()),
                               1.0 + GAMMA ** 3 * 2.0 + GAMMA ** 4 * 4.0, rtol=1e-6)


def test_template_learner_is_rewarded_by_its_satisfaction_not_the_environment():
    carry = (jnp.asarray([True, True, False]), jnp.zeros(3), jnp.zeros(3))
    acc = _account(carry, decided=[False, False, False], reward=[5.0, 5.0, 5.0],
                   env_done=[False] * 3, popped=_popped([1, D, 1], [True, False, True], [True, False, True]),
                   satisfied=[True, True, True], learner=2)
    # off the stack: no reward; not started: nothing recorded, episode does not count
    np.testing.assert_allclose(np.asarray(acc.reward), [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(np.asarray(acc.ends.finished), [True, False, False])
    np.testing.assert_allclose(np.asarray(acc.ends.success), [1.0, 0.0, 0.0])


@pytest.mark.parametrize("reset_on_end", [True, False])
def test_the_learners_end_resets_the_environment_only_when_asked(reset_on_end):
    carry = (jnp.ones(1, bool), jnp.zeros(1), jnp.asarray([2.0]))
    acc = _account(carry, decided=[False], reward=[0.0], env_done=[False],
                   popped=_popped([2], [True], [True]), satisfied=[True], learner=1,
                   reset_on_learner_end=reset_on_end)
    assert bool(acc.learner_done[0]) and bool(acc.reset[0]) == reset_on_end
    # the task's return survives a learner end only where the environment goes on
    assert float(acc.task_return[0]) == (0.0 if reset_on_end else 2.0)
    assert not bool(acc.ends.task_end[0])


def test_evaluation_counts_every_episode_and_the_environments_success():
    carry = (jnp.zeros(2, bool), jnp.zeros(2), jnp.zeros(2))
    acc = _account(carry, decided=[False, False], reward=[1.0, 0.0], env_done=[True, False],
                   popped=_popped([D, 0], [False, False], [False, False]), learner=NO_OPTION,
                   info_success=jnp.asarray([0.25, 0.75]))
    np.testing.assert_array_equal(np.asarray(acc.ends.finished), [True, True])  # the root popped
    np.testing.assert_allclose(np.asarray(acc.ends.success), [0.25, 0.75])
    np.testing.assert_allclose(np.asarray(acc.ends.ret), [1.0, 0.0])
    np.testing.assert_array_equal(np.asarray(acc.ends.task_end), [True, True])


def test_a_task_episode_only_counts_from_the_root_and_shaping_only_once_started():
    carry = (jnp.asarray([False, True]), jnp.zeros(2), jnp.zeros(2))
    acc = _account(carry, decided=[False, False], reward=[0.0, 0.0], env_done=[True, True],
                   popped=_popped([D, D], [True, True], [False, False]), learner=1, start=1,
                   shaping=jnp.asarray([0.5, 0.5]))
    assert not np.asarray(acc.ends.task_end).any()
    np.testing.assert_allclose(np.asarray(acc.reward), [0.0, 0.5])


# ---- realise and step ---------------------------------------------------------------
def test_primitive_action_broadcasts_to_the_action_shape():
    got = primitive_action(jnp.asarray([0, 2], jnp.int32), (3,), jnp.float32)
    chex.assert_shape(got, (2, 3))
    chex.assert_type(got, jnp.float32)
    np.testing.assert_array_equal(np.asarray(got), [[0, 0, 0], [2, 2, 2]])


def test_a_family_runs_each_environment_with_its_members_data():
    fn = lambda key, state, params, data: state + data  # noqa: E731
    other = lambda key, state, params: state * 0 - 1  # noqa: E731
    fams = families([Parametric(fn, jnp.asarray(10)), None, other, Parametric(fn, jnp.asarray(20))])
    assert len(fams) == 2  # templates 1 and 4 share fn; 3 is a family of its own
    state = jnp.asarray([1, 2, 3, 4])
    chosen = jnp.asarray([1, 4, NO_OPTION, 3])
    action = jnp.asarray([7, 7, 7, 7])
    got = run_family(fams, jax.random.PRNGKey(0), state, chosen, action, None, jnp.int32,
                     controls=True)
    np.testing.assert_array_equal(np.asarray(got), [11, 22, 7, -1])


def test_a_teleport_family_jumps_only_where_chosen():
    jump = lambda key, state, params: (state + 100, jnp.asarray(2))  # noqa: E731
    fams = families([jump])
    state, action = run_family(fams, jax.random.PRNGKey(0), jnp.asarray([1, 2]),
                               jnp.asarray([1, NO_OPTION]), jnp.asarray([0, 0]), None, jnp.int32,
                               controls=False)
    np.testing.assert_array_equal(np.asarray(state), [101, 2])
    np.testing.assert_array_equal(np.asarray(action), [2, 0])


def test_step_is_the_environment_step_of_each_environment():
    env = KeyDoor()
    params = env.default_params
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    _, state = jax.vmap(env.reset_env, (0, None))(keys, params)
    action = jnp.asarray([0, 1, 2])
    obs, new, reward, term, trunc, _ = phases.step(env, params, jax.random.PRNGKey(1), state, action)
    chex.assert_shape(obs, (3, env.observation_space(params).shape[0]))
    for b in range(3):
        one = jax.tree.map(lambda x: x[b], state)
        o, s, r, _, _, _ = env.step_env(None, one, action[b], params)
        np.testing.assert_array_equal(np.asarray(obs[b]), np.asarray(o))
        assert int(new.pos[b]) == int(s.pos) and float(reward[b]) == float(r)


# ---- evaluation without a learner ------------------------------------------------------
def test_evaluation_tick_needs_no_learner_state():
    """The episode runner (learner acts frozen) with nobody learning gives the same tick
    with no learner state as with one (whose network is not run)."""
    from types import SimpleNamespace

    from smjax.agents.base import Agent

    env = KeyDoor()
    h = env.hierarchies()["paper"]

    def logits(params, obs):
        return jnp.broadcast_to(params, (obs.shape[0], h.num_actions))

    agent = Agent("fixed", init=None, act=None, update=None, policy_logits=logits)
    runner = HierarchyRunner(env, env.default_params, h, agent)
    controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0), jnp.asarray([True, False]),
                        gamma=GAMMA, teleport=jnp.asarray(False), temperature=0.0,
                        acts_frozen=True)
    carry = runner.reset(jax.random.PRNGKey(0), controls, 5)
    bank = jnp.asarray([[0.0, 1.0, 0.5, 0.0], [0.0, 0.0, 0.0, 0.0]])
    own = SimpleNamespace(params=jnp.asarray([9.0, 0.0, 0.0, 0.0]))
    tick_with = jax.jit(lambda c, k: runner.tick(c, k, own, bank, controls))
    tick_without = jax.jit(lambda c, k: runner.tick(c, k, None, bank, controls))
    for t in range(4):
        k = jax.random.PRNGKey(t)
        with_l, without = tick_with(carry, k), tick_without(carry, k)
        chex.assert_trees_all_equal(with_l[0].env_state, without[0].env_state)
        chex.assert_trees_all_equal(with_l[1:], without[1:])
        carry = without[0]
    assert (np.asarray(carry.env_state.t) > 0).any()  # the root walked right
