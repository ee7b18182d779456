"""The policies' one-step memory (``policy_memory="last_action"``): the last primitive
action and whether it changed the observation, appended to what the policies see."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hier_env import KeyDoor, make_keydoor
from smjax.core import spaces
from smjax.options.memory import make_memory
from smjax.options.runner import Controls, HierarchyRunner
from smjax.train import ConfigError, TrainConfig
from smjax.train.run import run
from test_runner import fixed_agent


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 5), st.integers(2, 6), st.data())
def test_the_memory_is_the_last_action_and_whether_anything_moved(batch, num_actions, data):
    ints = st.lists(st.integers(0, 2), min_size=batch * 6, max_size=batch * 6)
    before = np.array(data.draw(ints), np.uint8).reshape(batch, 3, 2)
    after = np.array(data.draw(ints), np.uint8).reshape(batch, 3, 2)
    action = np.array(data.draw(st.lists(st.integers(0, num_actions - 1), min_size=batch,
                                         max_size=batch)), np.int32)
    memory = make_memory("last_action", spaces.Discrete(num_actions), before[0])
    start = np.asarray(memory.start(jnp.asarray(before)))
    assert start.shape == (batch, 6 + num_actions + 1) and start.dtype == np.uint8
    np.testing.assert_array_equal(start[:, :6], before.reshape(batch, 6))
    assert not start[:, 6:].any()  # a fresh episode remembers nothing
    out = np.asarray(memory.after(jnp.asarray(start), jnp.asarray(after), jnp.asarray(action)))
    np.testing.assert_array_equal(out[:, :6], after.reshape(batch, 6))
    np.testing.assert_array_equal(out[:, 6:-1], np.eye(num_actions, dtype=np.uint8)[action])
    np.testing.assert_array_equal(out[:, -1], (before != after).reshape(batch, -1).any(-1))


def test_a_box_action_is_remembered_as_its_values():
    memory = make_memory("last_action", spaces.Box(-1.0, 1.0, (2, 2)), jnp.zeros((3,)))
    out = memory.after(memory.start(jnp.zeros((4, 3))), jnp.ones((4, 3)),
                       jnp.full((4, 2, 2), 0.5))
    np.testing.assert_allclose(np.asarray(out), [[1, 1, 1, .5, .5, .5, .5, 1]] * 4)
    with pytest.raises(ValueError, match="policy_memory"):
        make_memory("lstm", spaces.Discrete(3), jnp.zeros((3,)))
    with pytest.raises(ConfigError, match="policy_memory"):
        TrainConfig(policy_memory="lstm")


def test_the_tick_remembers_the_executed_primitive():
    # the flat learner always steps left: once at the wall, the observation stops changing
    env = KeyDoor()
    h = env.hierarchies()["flat"]
    runner = HierarchyRunner(env, env.default_params, h, fixed_agent(0, h.num_actions),
                             policy_memory="last_action")
    controls = Controls(jnp.asarray(0), jnp.asarray(0), jnp.asarray([False]), gamma=0.9)
    carry = runner.reset(jax.random.PRNGKey(0), controls, 6)
    width = carry.obs.shape[1] - 4
    assert not np.asarray(carry.obs[:, width:]).any()
    tick = jax.jit(lambda c, k: runner.tick(c, k, None, jnp.zeros((1, 3)), controls))
    for t in range(12):
        pos = np.asarray(carry.env_state.pos)
        carry, _, ends = tick(carry, jax.random.PRNGKey(t))
        assert not np.asarray(ends.reset).any()
        memory = np.asarray(carry.obs[:, width:])
        np.testing.assert_array_equal(memory[:, :3], [[1, 0, 0]] * 6)
        np.testing.assert_array_equal(memory[:, 3], pos != np.asarray(carry.env_state.pos))
    assert not np.asarray(carry.obs[:, -1]).any()  # all at the wall now


def test_training_with_memory_shapes_every_policy():
    cfg = TrainConfig(num_envs=8, rollout_ticks=8, updates_per_chunk=2, success_window=32,
                      gate_envs=16, eval_envs=16, max_episodes_per_level=150,
                      finetune_max_episodes=160, finetune_turn_episodes=80,
                      policy_memory="last_action")
    res = run(make_keydoor(), cfg, [0], progress=False)
    assert 0.0 <= res["final_success"][0] <= 1.0 and res["finetune"]["episodes"][0] > 0
    # the policies' first layer reads the observation and the memory (3 actions + moved)
    kernel = jax.tree.leaves(res["_raw"]["bank"])
    widths = {leaf.shape[-2] for leaf in kernel if leaf.ndim == 4}
    assert 3 * 8 + 1 + 4 in widths, widths
