"""The hierarchical tick: teleport vs learned vs scripted dispatch, pops, SMDP discounts,
learner masks and rewards (with a scripted test double standing in for the learner)."""
import dataclasses
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hier_env import KeyDoor
from smjax.agents.base import ActOutput, Agent
from smjax.options.bank import frozen_temperature
from smjax.options.runner import NO_OPTION, Controls, HierarchyRunner

B = 6
GAMMA = 0.9


def fixed_agent(choice: int, num_actions: int) -> Agent:
    """Learner double: always picks ``choice``; frozen policies prefer argmax of their params."""
    def act(state, obs, mask, key):
        a = jnp.full((obs.shape[0],), choice, jnp.int32)
        return ActOutput(a, jnp.zeros(obs.shape[0]), jnp.zeros(obs.shape[0]))

    return Agent("fixed", init=lambda k, o, n: None, act=act, update=None,
                 policy_logits=lambda params, obs: jnp.broadcast_to(params, (obs.shape[0], num_actions)))


def setup(hname, learner_choice, bank_logits, learned, learner=0, start=0):
    env = KeyDoor()
    params = env.default_params
    h = env.hierarchies()[hname]
    agent = fixed_agent(learner_choice, h.num_actions)
    runner = HierarchyRunner(env, params, h, agent)
    controls = Controls(jnp.asarray(learner), jnp.asarray(start), jnp.asarray(learned),
                        gamma=GAMMA, temperature=0.0)
    carry = runner.reset(jax.random.PRNGKey(0), controls, B)
    bank = jnp.asarray(bank_logits, jnp.float32)
    tick = jax.jit(lambda c, k: runner.tick(c, k, None, bank, controls))
    return env, h, runner, carry, tick


def test_unlearned_template_is_teleported_in_one_tick():
    # root learner calls give_key (action 3); give_key is not learned -> teleport
    env, h, runner, carry, tick = setup("paper", 3, np.zeros((2, 4)), [False, False])
    carry2, tr, ends = tick(carry, jax.random.PRNGKey(1))
    assert bool(carry2.env_state.has_key.all() | ends.reset.any())
    assert bool(tr.decision.all())
    np.testing.assert_allclose(np.asarray(tr.discount), GAMMA ** 4, rtol=1e-6)  # nominal_steps = 4
    assert (np.asarray(carry2.stack.depth) == 1).all()  # teleports are not pushed
    np.testing.assert_array_equal(np.asarray(carry2.env_state.t), 1)  # exactly one env step


def test_learned_template_is_pushed_and_runs_its_frozen_policy_until_k_max():
    bank = np.zeros((2, 4))
    bank[1, 0] = 5.0  # the learned give_key always walks left (never grabs the key)
    env, h, runner, carry, tick = setup("paper", 3, bank, [False, True])
    # put every agent right of its key so walking left never stands on it in time to USE
    carry = carry.replace(env_state=carry.env_state.replace(pos=jnp.full((B,), 7)))
    decisions = []
    for t in range(14):
        carry, tr, ends = tick(carry, jax.random.PRNGKey(t))
        decisions.append(np.asarray(tr.decision))
        if t == 0:
            assert (np.asarray(carry.stack.depth) == 2).all()
            assert (np.asarray(carry.stack.option[:, 1]) == h.option_index("give_key")).all()
            np.testing.assert_allclose(np.asarray(tr.discount), GAMMA)
    decisions = np.array(decisions)
    assert decisions[0].all()
    # while give_key runs (k_max = 12 ticks) the learner does not decide; then it decides again
    assert not decisions[1:12].any()
    assert decisions[12].all()
    assert not np.asarray(carry.env_state.has_key).any()


def test_scripted_controller_is_pushed_and_pops_when_satisfied():
    h_scripted = KeyDoor().hierarchies()["scripted"]
    reach = h_scripted.action_index("reach_door")
    env, h, runner, carry, tick = setup("scripted", reach, np.zeros((3, 5)), [False, False, False])
    carry = carry.replace(env_state=carry.env_state.replace(
        pos=jnp.zeros((B,), jnp.int32), door_pos=jnp.full((B,), 6)))
    for t in range(6):
        carry, tr, _ = tick(carry, jax.random.PRNGKey(t))
        assert (np.asarray(carry.env_state.pos) == t + 1).all()
        expected_depth = 2 if t < 5 else 1  # pops on the tick the door is reached
        assert (np.asarray(carry.stack.depth) == expected_depth).all()
        assert bool(tr.decision.all()) == (t == 0)


def test_template_learner_reward_is_satisfaction_and_its_end_resets():
    bank = np.zeros((2, 4))
    bank[0, 3] = 5.0  # the learned root calls give_key, which is the learner
    env, h, runner, carry, tick = setup("paper", 2, bank, [True, False], learner=1)
    carry = carry.replace(env_state=carry.env_state.replace(pos=carry.env_state.key_pos))
    carry2, tr, ends = tick(carry, jax.random.PRNGKey(3))
    assert bool(tr.decision.all())  # pushed and decided in the same tick
    np.testing.assert_allclose(np.asarray(tr.reward), 1.0)
    assert bool(tr.done.all()) and bool(ends.finished.all())
    np.testing.assert_allclose(np.asarray(ends.success), 1.0)
    assert (np.asarray(carry2.env_state.t) == 0).all()  # reset after the learner's episode


def test_learner_masks_respect_children_and_initiation():
    env, h, runner, carry, tick = setup("paper", 3, np.zeros((2, 4)), [False, False], learner=1)
    bank = jnp.zeros((2, 4))
    controls = Controls(jnp.asarray(1), jnp.asarray(0), jnp.asarray([True, False]), gamma=GAMMA)
    _, tr, _ = runner.tick(carry, jax.random.PRNGKey(0), None, bank, controls)
    # give_key's own children are the primitives only
    np.testing.assert_array_equal(np.asarray(tr.action_mask[0]), [True, True, True, False])
    masks = jax.vmap(lambda s: runner.action_masks(runner._initiation(s),
                                                   runner.callable_options(
                                                       controls.learned, controls.learner,
                                                       runner.teleports_on(controls))))(
        carry.env_state.replace(has_key=jnp.ones(B, bool)))
    assert not np.asarray(masks[:, 0, 3]).any()  # give_key can't be called while holding the key


def test_evaluation_runner_never_teleports():
    env = KeyDoor()
    h = env.hierarchies()["paper"]
    agent = fixed_agent(0, h.num_actions)
    runner = HierarchyRunner(env, env.default_params, h, agent)
    controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0), jnp.asarray([True, False]),
                        gamma=GAMMA, teleport=False)
    carry = runner.reset(jax.random.PRNGKey(0), controls, B)
    bank = jnp.zeros((2, 4)).at[0, 3].set(9.0)  # root would love to call give_key
    carry2, tr, _ = runner.tick(carry, jax.random.PRNGKey(1), None, bank, controls)
    # give_key is neither learned nor scripted, so it is masked out: nobody teleports
    assert not np.asarray(carry2.env_state.has_key).any()
    assert not np.asarray(tr.decision).any()


def test_learner_acting_frozen_takes_its_greedy_masked_choice():
    # the acceptance gate's runner: the learner ignores its exploring act() (always "left")
    # and picks as the bank would run it: argmax of its own scores among allowed actions
    from types import SimpleNamespace

    env = KeyDoor()
    h = env.hierarchies()["paper"]
    runner = HierarchyRunner(env, env.default_params, h, fixed_agent(0, h.num_actions))
    controls = Controls(jnp.asarray(0), jnp.asarray(0), jnp.asarray([False, False]), gamma=GAMMA,
                        temperature=0.0, acts_frozen=True)
    carry = runner.reset(jax.random.PRNGKey(0), controls, B)
    bank = jnp.zeros((2, 4))
    # scores prefer give_key (3), then use (2); give_key is masked out while the key is held
    own = SimpleNamespace(params=jnp.asarray([0.0, 0.5, 1.0, 2.0]))
    holding = np.arange(B) % 2 == 0
    carry = carry.replace(env_state=carry.env_state.replace(has_key=jnp.asarray(holding)))
    _, tr, _ = runner.tick(carry, jax.random.PRNGKey(1), own, bank, controls)
    assert np.asarray(tr.decision).all()
    np.testing.assert_array_equal(np.asarray(tr.action), np.where(holding, 2, 3))


def test_per_option_temperature_samples_the_root_and_picks_greedily_below_it():
    # Controls.temperature [O]: each frozen option picks at its own temperature (the root
    # sampling at 1 while the template below it picks at 0); the learner at its own entry
    env = KeyDoor()
    h = env.hierarchies()["paper"]
    runner = HierarchyRunner(env, env.default_params, h, fixed_agent(0, h.num_actions))
    flat = jnp.zeros((2, 512, h.num_actions)).at[:, :, 2].set(0.5)  # nearly uniform scores
    controls = Controls(jnp.asarray(1), jnp.asarray(0), jnp.asarray([True, True]), gamma=GAMMA,
                        temperature=jnp.asarray([1.0, 0.0]))
    picks = np.asarray(runner._frozen_pick(flat, jax.random.PRNGKey(3), controls))
    assert (picks[1] == 2).all()                        # the template: argmax, every time
    assert len(set(picks[0].tolist())) == h.num_actions  # the root: a sample
    learner = np.asarray(runner._frozen_pick(flat[0], jax.random.PRNGKey(4), controls,
                                             controls.learner))
    assert (learner == 2).all()                          # the learner is option 1: greedy
    root = dataclasses.replace(controls, learner=jnp.asarray(0))
    learner = np.asarray(runner._frozen_pick(flat[0], jax.random.PRNGKey(4), root, root.learner))
    assert len(set(learner.tolist())) == h.num_actions


def test_a_ticks_settings_come_with_its_controls_alone():
    # the runner is built from the program's structure; gamma has no default
    env = KeyDoor()
    h = env.hierarchies()["paper"]
    for setting, value in (("gamma", 0.9), ("frozen_policy", "sample"), ("allow_teleport", False),
                           ("reset_on_learner_end", False), ("learner_acts_frozen", True)):
        with pytest.raises(TypeError, match=setting):
            HierarchyRunner(env, env.default_params, h, fixed_agent(0, 4), **{setting: value})
    with pytest.raises(TypeError, match="gamma"):
        Controls(jnp.asarray(0), jnp.asarray(0), jnp.asarray([False, False]))


def test_frozen_policy_mode_is_validated():
    with pytest.raises(ValueError, match="frozen_policy"):
        frozen_temperature("best", 1.0, 2)


def test_failed_condition_pops_without_reward():
    import dataclasses

    from smjax.options import Hierarchy
    env = KeyDoor()
    tpls = dict(env.templates())
    # reach_door as the learner's child, failing after 2 ticks (before the door is reached)
    tpls["reach_door"] = dataclasses.replace(tpls["reach_door"], failed=lambda s, p: s.t >= 2)
    h = Hierarchy("open_door", {"open_door": ["reach_door", "use"]}, tpls, env.primitive_action_names)
    reach = h.action_index("reach_door")
    runner = HierarchyRunner(env, env.default_params, h, fixed_agent(reach, h.num_actions))
    controls = Controls(jnp.asarray(0), jnp.asarray(0), jnp.asarray([False, False]), gamma=GAMMA)
    carry = runner.reset(jax.random.PRNGKey(0), controls, B)
    carry = carry.replace(env_state=carry.env_state.replace(
        pos=jnp.zeros((B,), jnp.int32), door_pos=jnp.full((B,), 7)))
    bank = jnp.zeros((2, h.num_actions))
    depths = []
    for t in range(3):
        carry, tr, _ = runner.tick(carry, jax.random.PRNGKey(t), None, bank, controls)
        depths.append(int(carry.stack.depth[0]))
        assert float(tr.reward.sum()) == 0.0
    # pushed; popped by `failed` once t = 2; called again, it fails again at once
    assert depths == [2, 1, 1]
    assert (np.asarray(carry.env_state.pos) == 3).all()  # its controller still walked each tick


@pytest.mark.parametrize("held_all_along", [False, True])
@pytest.mark.parametrize("switch", [None, False, True])
def test_side_cost_shapes_only_a_template_learners_reward_and_only_when_asked(switch,
                                                                              held_all_along):
    """Reward = F_o + c(s) - c(s') with the switch on (undiscounted: holding a cost that
    does not change earns nothing); F_o alone otherwise; the recorded success stays F_o
    either way."""
    import dataclasses
    env = KeyDoor()
    h = env.hierarchies()["paper"]
    # grows every tick, or (held_all_along) a cost the option was called with and keeps
    grows = 0.0 if held_all_along else 0.1
    cost = lambda s, p: grows * s.t.astype(jnp.float32) + 0.05  # noqa: E731
    tpls = {**h.templates, "give_key": dataclasses.replace(h.templates["give_key"], side_cost=cost)}
    h = dataclasses.replace(h, templates=tpls)
    runner = HierarchyRunner(env, env.default_params, h, fixed_agent(2, h.num_actions))
    on = None if switch is None else jnp.asarray(switch)
    controls = Controls(jnp.asarray(1), jnp.asarray(0), jnp.asarray([True, False]), gamma=GAMMA,
                        temperature=0.0, side_cost=on)
    carry = runner.reset(jax.random.PRNGKey(0), controls, B)
    carry = carry.replace(env_state=carry.env_state.replace(pos=carry.env_state.key_pos,
                                                            t=jnp.full((B,), 3)))
    bank = np.zeros((2, 4))
    bank[0, 3] = 5.0  # the learned root calls give_key, the learner, which is satisfied at once
    _, tr, ends = runner.tick(carry, jax.random.PRNGKey(3), None, jnp.asarray(bank, jnp.float32),
                              controls)
    shaped = 1.0 + (grows * 3 + 0.05) - (grows * 4 + 0.05)  # 1.0 exactly where nothing grows
    np.testing.assert_allclose(np.asarray(tr.reward), shaped if switch else 1.0, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(ends.success), 1.0)


def test_craft_side_cost_charges_items_other_than_the_promised_one():
    from smjax.envs.craft import constants as C
    from smjax.envs.craft.templates import make_templates
    import smjax
    env, params = smjax.make("craft/get_gem", observation="none")
    state = env.initial_state(jax.random.PRNGKey(0), params)
    inv = state.inventory.at[C.KIND_ID["wood"]].set(2).at[C.KIND_ID["iron"]].set(1)
    state = state.replace(inventory=inv)
    tpls = make_templates()
    np.testing.assert_allclose(float(tpls["give_wood"].side_cost(state, params)), 0.1)
    np.testing.assert_allclose(float(tpls["give_iron"].side_cost(state, params)), 0.2)
    np.testing.assert_allclose(float(tpls["give_axe"].side_cost(state, params)), 0.3)


def test_craft_surplus_and_leftover_side_costs_leave_the_recipe_ingredients_free():
    """``--env side_cost=surplus``: a give_X run is charged only for units beyond what X's
    recipe tree consumes (so gathering ingredients costs nothing), never more than "held";
    ``leftover`` charges as "surplus" while X is missing and as "held" once X is held."""
    from hypothesis import given, settings, strategies as st
    from smjax.envs.craft import constants as C
    from smjax.envs.craft.templates import recipe_counts
    import smjax
    env, params = smjax.make("craft/get_gem", observation="none", side_cost="surplus")
    kinds = {k: smjax.make("craft/get_gem", observation="none", side_cost=k)[0].templates()
             for k in ("held", "leftover")}
    base = env.initial_state(jax.random.PRNGKey(0), params)
    assert recipe_counts("ladder") == {"plank": 1, "stick": 1, "wood": 2}
    for item in C.ITEMS:  # every node of the tree below the item, counted with multiplicity
        assert sum(recipe_counts(item).values()) == C.tree_size(item) - 1
    names = ["give_axe", "give_stick", "give_wood", "give_bridge", "give_ladder"]
    costs = {n: jax.jit(env.templates()[n].side_cost) for n in names}
    held_costs = {n: jax.jit(kinds["held"][n].side_cost) for n in names}
    leftover_costs = {n: jax.jit(kinds["leftover"][n].side_cost) for n in names}

    @settings(max_examples=40, deadline=None)
    @given(st.sampled_from(names), st.lists(st.integers(0, 3), min_size=len(C.ITEMS),
                                            max_size=len(C.ITEMS)))
    def check(name, counts):
        inv = base.inventory.at[len(C.KIND_NAMES) - len(C.ITEMS):].set(jnp.asarray(counts))
        state = base.replace(inventory=inv.astype(base.inventory.dtype))
        item = name.removeprefix("give_")
        need = recipe_counts(item)
        want = 0.1 * sum(max(0, n - need.get(k, 0))
                         for k, n in zip(C.ITEMS, counts) if k != item)
        got = float(costs[name](state, params))
        np.testing.assert_allclose(got, want, atol=1e-5)
        held_cost = float(held_costs[name](state, params))
        assert got <= held_cost + 1e-6
        has_x = counts[C.ITEMS.index(item)] > 0
        np.testing.assert_allclose(float(leftover_costs[name](state, params)),
                                   held_cost if has_x else got, atol=1e-6)

    check()
    with pytest.raises(ValueError, match="side_cost must be one of"):
        smjax.make("craft/get_gem", side_cost="everything")
