"""Scripted policies of options with children (``Hierarchy.policies``): followed exactly
where nothing learned decides, never for the learner's own option, second to a learned
policy and to a teleport; a fully scripted hierarchy runs without an agent (KeyDoor of
tests/hier_env.py, and Fetch's ``scripted`` hierarchy)."""
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hier_env import N, KeyDoor
from smjax.options import HierarchyError, declare
from smjax.options.runner import NO_OPTION, Controls, HierarchyRunner
from test_runner import fixed_agent

B = 8
LEFT, RIGHT, USE = 0, 1, 2


def always(child: int):
    def policy(key, state, params, mask):
        return jnp.asarray(child)
    return policy


def run(h, ticks, *, agent=None, bank=None, learner=NO_OPTION, learned=None, teleport=False,
        start_pos=None, seed=0):
    """States after each of ``ticks`` ticks (and the transitions)."""
    env = KeyDoor()
    runner = HierarchyRunner(env, env.default_params, h, agent)
    learned = np.zeros(h.num_options, bool) if learned is None else np.asarray(learned)
    controls = Controls(jnp.asarray(learner), jnp.asarray(0), jnp.asarray(learned), gamma=0.9,
                        teleport=teleport)
    carry = runner.reset(jax.random.PRNGKey(seed), controls, B)
    if start_pos is not None:
        carry = carry.replace(env_state=carry.env_state.replace(pos=jnp.full((B,), start_pos)))
    tick = jax.jit(lambda c, k: runner.tick(c, k, None, bank, controls))
    states, trs, ends = [carry.env_state], [], []
    for t in range(ticks):
        carry, tr, e = tick(carry, jax.random.PRNGKey(100 + t))
        states.append(carry.env_state), trs.append(tr), ends.append(e)
    return states, trs, ends, carry


@pytest.mark.parametrize("child,move", [(0, -1), (1, 1)])
def test_a_scripted_root_is_followed_exactly(child, move):
    env = KeyDoor()
    h = declare(env, "open_door", {"open_door": ["primitives"]},
                policies={"open_door": always(child)})
    states, _, ends, _ = run(h, 5, start_pos=3)
    for before, after, e in zip(states, states[1:], ends):
        assert not np.asarray(e.reset).any()
        np.testing.assert_array_equal(np.asarray(after.pos),
                                      np.clip(np.asarray(before.pos) + move, 0, N - 1))


def test_a_scripted_root_calls_a_template_child():
    env = KeyDoor()
    # root -> reach_door (child 1, a controller) every time it decides
    h = declare(env, "open_door", {"open_door": ["give_key", "reach_door", "use"],
                                   "give_key": ["primitives"]},
                policies={"open_door": always(1)})
    states, _, _, carry = run(h, 1, start_pos=0)
    assert (np.asarray(carry.stack.option)[:, 1] == h.option_index("reach_door")).all() | \
        (np.asarray(states[1].pos) == np.asarray(states[1].door_pos)).all()
    np.testing.assert_array_equal(np.asarray(states[1].pos), 1)  # walked right towards the door


def test_the_policy_sees_its_childrens_mask():
    env = KeyDoor()
    # reach_door may be called only away from the door (its initiation): the mask says so
    def by_mask(key, state, params, mask):
        return jnp.where(mask[0], 2, 1)  # reach_door allowed -> use, else left

    h = declare(env, "open_door", {"open_door": ["reach_door", "left", "use"]},
                policies={"open_door": by_mask})
    states, _, _, _ = run(h, 1, start_pos=4)
    at_door = np.asarray(states[0].door_pos) == 4
    assert at_door.any() and not at_door.all()
    np.testing.assert_array_equal(np.asarray(states[1].pos), np.where(at_door, 3, 4))


def test_a_forbidden_pick_becomes_the_first_allowed_child():
    env = KeyDoor()
    # the script always calls reach_door, which is not initiable at the door: there the
    # runner takes the first allowed child instead ("left"); elsewhere the script is obeyed
    h = declare(env, "open_door", {"open_door": ["reach_door", "left", "use"]},
                policies={"open_door": always(0)})
    states, _, _, carry = run(h, 1, start_pos=4)
    at_door = np.asarray(states[0].door_pos) == 4
    assert at_door.any() and not at_door.all()
    np.testing.assert_array_equal(np.asarray(states[1].pos)[at_door], 3)
    called = np.asarray(carry.stack.option)[:, 1] == h.option_index("reach_door")
    assert not called[at_door].any()
    moved_right = np.asarray(states[1].pos)[~at_door] == 5
    assert (called[~at_door] | moved_right).all()


def test_the_learners_own_option_ignores_its_scripted_policy():
    env = KeyDoor()
    h = declare(env, "open_door", {"open_door": ["primitives"]},
                policies={"open_door": always(LEFT)})
    agent = fixed_agent(RIGHT, h.num_actions)
    states, trs, _, _ = run(h, 3, agent=agent, bank=jnp.zeros((1, 3)), learner=0, start_pos=3)
    for before, after, tr in zip(states, states[1:], trs):
        np.testing.assert_array_equal(np.asarray(after.pos), np.asarray(before.pos) + 1)
        assert np.asarray(tr.decision).all()          # every decision is the learner's


def test_a_learned_policy_comes_before_the_script():
    env = KeyDoor()
    h = declare(env, "open_door", {"open_door": ["primitives"]},
                policies={"open_door": always(LEFT)})
    bank = np.zeros((1, 3), np.float32)
    bank[0, RIGHT] = 5.0  # the frozen root walks right
    agent = fixed_agent(USE, h.num_actions)
    states, trs, _, _ = run(h, 2, agent=agent, bank=jnp.asarray(bank), learned=[True],
                            start_pos=3)
    np.testing.assert_array_equal(np.asarray(states[2].pos), 5)
    assert not np.asarray(trs[0].decision).any()     # nobody learns


def _to_key(key, state, params, mask):                       # give_key over primitives
    return jnp.where(state.pos < state.key_pos, RIGHT, jnp.where(state.pos > state.key_pos,
                                                                 LEFT, USE))


def _open(key, state, params, mask):                         # open_door's rule
    return jnp.where(~state.has_key, 0, jnp.where(state.pos != state.door_pos, 1, 2))


def _scripted_keydoor():
    base = KeyDoor().hierarchies()["scripted"]
    return declare(KeyDoor(), base.task, base.children,
                   policies={"open_door": _open, "give_key": _to_key})


def test_a_fully_scripted_hierarchy_opens_every_door_without_an_agent():
    h = _scripted_keydoor()
    assert set(h.scripted) == {"open_door", "give_key"} and "[scripted policy]" in h.describe()
    _, _, ends, _ = run(h, 30)
    first = np.zeros(B, bool)
    success = np.zeros(B)
    for e in ends:
        end = np.asarray(e.task_end) & ~first
        success = np.where(end, np.asarray(e.task_success), success)
        first |= end
    assert first.all() and (success == 1.0).all()


def test_the_engine_evaluates_a_scripted_hierarchy_with_nothing_learned():
    from smjax.agents import make_agent
    from smjax.train.config import TrainConfig
    from smjax.train.engine import Engine

    env, h = KeyDoor(), _scripted_keydoor()
    cfg = TrainConfig(method="top-down", algo="ppo", num_envs=4, eval_envs=8)
    engine = Engine(env, env.default_params, h, make_agent("ppo"), cfg)
    bank = engine.new_bank(engine.init_learner(jax.random.split(jax.random.PRNGKey(0), 1)))
    learned = jnp.zeros((1, h.num_options), bool)
    result, _ = engine.evaluate(jax.random.split(jax.random.PRNGKey(1), 1), bank, learned)
    assert float(result["completed"][0]) == 1.0 and float(result["success"][0]) == 1.0


def test_a_teleport_comes_before_a_scripted_template_policy():
    h = _scripted_keydoor()
    states, _, _, carry = run(h, 1, teleport=True)
    # give_key (no key at reset) is teleported: one tick, key held, nothing pushed
    assert np.asarray(states[1].has_key).all()
    np.testing.assert_array_equal(np.asarray(carry.stack.depth), 1)
    states, _, _, carry = run(h, 1, teleport=False)
    assert (np.asarray(carry.stack.option)[:, 1] == h.option_index("give_key")).all()


def test_policies_are_validated():
    env = KeyDoor()
    children = {"open_door": ["give_key", "primitives"], "give_key": ["primitives"]}
    with pytest.raises(HierarchyError, match="reach_door"):
        declare(env, "open_door", children, policies={"reach_door": always(0)})
    with pytest.raises(HierarchyError, match="must be a function"):
        declare(env, "open_door", children, policies={"open_door": 3})
    with pytest.raises(HierarchyError, match="policies must map"):
        declare(env, "open_door", children, policies=[always(0)])


@pytest.mark.slow  # ~60 s compiling MJX; the runner's scripted path is tested on KeyDoor above
def test_fetch_scripted_hierarchy_stacks_blocks():
    """Fetch's ``scripted`` hierarchy, played by the runner with no agent, stacks two
    blocks (a random root scores about 0.5 or less: the scripts place them, bottom up)."""
    import smjax

    env, params = smjax.make("fetch/stack2")
    h = env.hierarchies()["scripted"]
    runner = HierarchyRunner(env, params, h, None)
    controls = Controls(jnp.asarray(NO_OPTION), jnp.asarray(0), jnp.zeros(h.num_options, bool),
                        gamma=1.0, teleport=False)
    n = 4
    horizon = int(params.max_steps)

    @jax.jit
    def episodes(key):
        k_reset, k_run = jax.random.split(key)
        carry = runner.reset(k_reset, controls, n)

        def tick(c, k):
            c, tr, ends = runner.tick(c, k, None, None, controls)
            return c, (ends.task_end, ends.task_success, tr.decision)

        _, out = jax.lax.scan(tick, carry, jax.random.split(k_run, horizon))
        return out

    end, success, decision = (np.asarray(x) for x in episodes(jax.random.PRNGKey(0)))
    assert not decision.any()                              # nobody learns
    np.testing.assert_array_equal(end.sum(0), 1)           # one episode each, to its end
    score = success.sum(0)
    assert score.mean() > 0.8, score
