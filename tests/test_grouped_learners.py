"""The actor-critic's and DQN's learners per option updated at once
(``actor_critic_options``, ``dqn_options``): the same result as each option's own
update, each option from its own decisions only."""
import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from smjax.agents import make_agent
from smjax.agents.option_batch import each_option, joint_batch
from smjax.core.transition import Transition
from _helpers import assert_trees_close, joint_record, pending_rows

T, B, A, F = 9, 6, 5, 7
# decision rates of the options: many, few, none at all, some
RATES = (0.7, 0.04, 0.0, 0.3)
O = len(RATES)
IDLE = 2


def _record(seed: int, rates=RATES) -> Transition:
    """A random joint record [T, B, O] (obs shared), option o deciding at rate rates[o]."""
    return joint_record(seed, (T, B, O, A, F),
                        lambda k: jax.random.uniform(k, (T, B, O)) < jnp.asarray(rates),
                        reward_scale=3.0, done_rate=0.1)


def _pending(seed: int) -> Transition:
    return pending_rows(seed, O, B, F, A, IDLE)


def _states(agent, seed: int):
    """Every option's learner, with hyper-parameters that differ between options."""
    keys = jax.random.split(jax.random.PRNGKey(seed + 200), O)
    states = jax.tree.map(lambda *x: jnp.stack(x), *[agent.init(k, jnp.zeros((F,)), A)
                                                     for k in keys])
    scale = {"learning_rate": jnp.asarray([1.0, 3.0, 0.5, 2.0]),
             "vf_coef": jnp.asarray([2.0, 0.5, 3.0, 1.0]),
             "reward_scale": jnp.asarray([1.0, 0.5, 2.0, 1.5])}
    return states.replace(hp={k: v * scale.get(k, 1.0) for k, v in states.hp.items()})




def _agent(algo="actor-critic", **config):
    return make_agent(algo, hidden_sizes=(16,), option_update="grouped", **config)


CONFIGS = {
    "paper": {},
    "normalized": dict(normalize_advantages=True, max_grad_norm=0.5, ent_coef=0.01),
    "shared": dict(shared_torso=True, bootstrap_at_rollout_end=False, ent_coef=0.05),
}


@pytest.mark.parametrize("block,per_step", [(1, 1), (4, 1), (128, 1), (4, 8)])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_the_grouped_update_equals_each_options_update(name, block, per_step):
    # the same parameters, optimiser states (Adam's first moment is the gradient scaled:
    # the gradients agree), counters and metrics as update() option by option, whatever
    # the block size (one row, blocks that split an option's decisions, one for them all)
    # and however many blocks a pass of the loop takes
    agent = _agent(option_block=block, option_blocks_per_step=per_step, **CONFIGS[name])
    batch, _ = joint_batch(_pending(block), _record(block))
    states, key = _states(agent, block), jax.random.PRNGKey(3)
    grouped, g_metrics = jax.jit(agent.update_options)(states, batch, key)
    alone, a_metrics = jax.jit(each_option(agent.update))(states, batch, key)
    decisions = np.asarray(a_metrics["decisions"])
    assert decisions[IDLE] == 0 and decisions[0] > 4 * decisions[1] > 0  # uneven counts
    chex.assert_trees_all_equal_shapes_and_dtypes(grouped, alone)
    chex.assert_tree_all_finite((grouped.params, grouped.opt_state, g_metrics))
    assert_trees_close(grouped, alone, rtol=2e-4, atol=2e-6)
    assert g_metrics.keys() == a_metrics.keys()
    for metric in a_metrics:
        chex.assert_equal_shape([g_metrics[metric], a_metrics[metric]])
        np.testing.assert_allclose(np.asarray(g_metrics[metric]), np.asarray(a_metrics[metric]),
                                   rtol=2e-4, atol=2e-6, err_msg=metric)
    np.testing.assert_array_equal(np.asarray(grouped.grad_steps), decisions > 0)
    idle = lambda tree: jax.tree.map(lambda x: np.asarray(x[IDLE]), tree)  # noqa: E731
    assert_trees_close(idle((grouped.params, grouped.opt_state)), idle((states.params, states.opt_state)),
           rtol=0, atol=0)


def _changed_elsewhere(mine):
    """The batch, and one whose options outside ``mine`` have other decisions, rewards and
    pending rows (the shared observations stay)."""
    traj, other = _record(0), _record(1, rates=(0.2, 0.6, 0.5, 0.1))
    changed = jax.tree.map(lambda a, b: jnp.where(mine.reshape((O,) + (1,) * (a.ndim - 3)), a, b),
                           traj._replace(obs=None), other._replace(obs=None))
    pending, other_pending = _pending(0), _pending(1)
    changed_pending = jax.tree.map(lambda a, b: jnp.where(
        mine.reshape((O,) + (1,) * (a.ndim - 1)), a, b), pending, other_pending)
    return (joint_batch(pending, traj)[0],
            joint_batch(changed_pending, changed._replace(obs=traj.obs))[0])


@pytest.mark.parametrize("algo", ["actor-critic", "dqn"])
def test_each_option_learns_only_from_its_own_decisions(algo):
    # the others' decisions, rewards and pending rows changed: options 0 and 3 end exactly
    # where they did; a changed option does not
    config = (dict(option_block=4, normalize_advantages=True) if algo == "actor-critic"
              else DQN_SMALL)
    agent = _agent(algo, **config)
    states, key = _states(agent, 0), jax.random.PRNGKey(0)
    mine = jnp.asarray([True, False, False, True])
    batch, changed = _changed_elsewhere(mine)
    update = jax.jit(agent.update_options)
    new, _ = update(states, batch, key)
    new_changed, _ = update(states, changed, key)
    kept = lambda tree: jax.tree.map(lambda x: np.asarray(x)[np.asarray(mine)], tree)  # noqa: E731
    assert_trees_close(kept(new_changed), kept(new), rtol=0, atol=0)
    moved = jax.tree.map(lambda a, b: np.abs(np.asarray(a[1]) - np.asarray(b[1])).max(),
                         new.params, new_changed.params)
    assert max(jax.tree.leaves(moved)) > 0


# a buffer smaller than option 0's decisions of one rollout (the oldest are dropped), that
# wraps around; steps from the first update on
DQN_SMALL = dict(buffer_capacity=40, batch_size=8, learning_starts=10,
                 gradient_steps_per_update=3, target_update_period=2)


@pytest.mark.parametrize("config", [DQN_SMALL, dict(DQN_SMALL, double_dqn=False, tau=0.5,
                                                    reward_scale=0.3, buffer_capacity=300)])
def test_the_grouped_dqn_update_equals_each_options_update(config):
    # two updates in a row: the same buffers (rows copied, to the bit), parameters, target
    # networks, optimiser states, counters and metrics as update() option by option
    agent = _agent("dqn", **config)
    states = _states(agent, 5)
    states = states.replace(buffer=states.buffer.replace(
        insert_pos=jnp.asarray([0, 5, 39, 17], jnp.int32) % config["buffer_capacity"]))
    grouped, alone = states, states
    for r, seed in enumerate((5, 6)):
        batch, key = joint_batch(_pending(seed), _record(seed))[0], jax.random.PRNGKey(r)
        grouped, g_metrics = jax.jit(agent.update_options)(grouped, batch, key)
        alone, a_metrics = jax.jit(each_option(agent.update))(alone, batch, key)
        chex.assert_trees_all_equal_shapes_and_dtypes(grouped, alone)
        chex.assert_tree_all_finite((grouped.params, grouped.opt_state, g_metrics))
        assert_trees_close(grouped.buffer, alone.buffer, rtol=0, atol=0)
        assert_trees_close(grouped, alone, rtol=2e-5, atol=1e-6)
        assert g_metrics.keys() == a_metrics.keys()
        assert_trees_close([g_metrics[k] for k in sorted(a_metrics)], [a_metrics[k] for k in sorted(a_metrics)],
               rtol=2e-5, atol=1e-6)
    decisions = np.asarray(a_metrics["decisions"])
    assert decisions[IDLE] == 0 and decisions[0] > 4 * decisions[1] > 0
    assert (np.asarray(alone.grad_steps)[[0, 3]] == 6).all()  # both updates stepped


@pytest.mark.parametrize("algo", ["actor-critic", "dqn"])
def test_the_grouped_update_is_chosen_unless_named(algo):
    assert _agent(algo).update_options is not None
    assert make_agent(algo, option_update="per_option").update_options is None
    assert make_agent(algo).update_options is not None  # auto: grouped on every backend
    with pytest.raises(ValueError, match="option_update"):
        make_agent(algo, option_update="sometimes")


def test_the_actor_critic_refuses_an_empty_block():
    with pytest.raises(ValueError, match="option_block"):
        make_agent("actor-critic", option_block=0)
