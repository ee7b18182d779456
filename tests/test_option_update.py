"""A learner per option updated at the price of one (``Agent.update_options``): the same
result as each option's own update, each option from its own decisions only."""
import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from smjax.agents import make_agent
from smjax.agents.grouped import blocks_per_step, grouped_grads
from smjax.agents.option_batch import each_option, joint_batch
from smjax.agents.smdp import carry_pending
from smjax.core.transition import Transition
from smjax.options.joint import OPTION_AXES
from _helpers import assert_trees_close, joint_record, pending_rows

T, B, O, A, F = 7, 5, 4, 6, 9
IDLE = 2  # an option with no decision in the record


def _record(seed: int) -> Transition:
    """A random joint record [T, B, O] (obs shared); option IDLE never decides."""
    return joint_record(seed, (T, B, O, A, F), lambda k: jax.random.bernoulli(
        k, 0.4, (T, B, O)).at[:, :, IDLE].set(False))


def _pending(seed: int) -> Transition:
    return pending_rows(seed, O, B, F, A, IDLE)


def _states(agent, seed: int):
    keys = jax.random.split(jax.random.PRNGKey(seed + 200), O)
    return jax.tree.map(lambda *x: jnp.stack(x),
                        *[agent.init(k, jnp.zeros((F,)), A) for k in keys])




def test_the_batch_carries_pending_rows_as_each_option_did():
    # the one-table batch holds, per option, what carry_pending over that option's record
    # (observations copied) gave, and the same new pending rows
    traj, pending = _record(0), _pending(0)
    batch, new_pending = joint_batch(pending, traj)
    want, want_pending = jax.vmap(carry_pending, (0, OPTION_AXES))(pending, traj)
    assert_trees_close(batch.traj._replace(obs=batch.observations()), want, rtol=0, atol=0)
    assert_trees_close(new_pending, want_pending, rtol=0, atol=0)


@pytest.mark.parametrize("block,per_step", [(1, 1), (3, 1), (128, 1), (3, 4), (1, 16)])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_grouped_update_equals_each_options_update(block, per_step, seed):
    # same parameters, optimiser states, counters and metrics as update() option by
    # option, whatever the block size (one row, blocks that split an option's decisions,
    # one block holding them all) and however many blocks a pass of the loop takes
    agent = make_agent("ppo", hidden_sizes=(16, 16), num_minibatches=3, update_epochs=2,
                       option_block=block, option_blocks_per_step=per_step, target_kl=0.05)
    batch, _ = joint_batch(_pending(seed), _record(seed))
    states, key = _states(agent, seed), jax.random.PRNGKey(seed + 7)
    grouped, g_metrics = jax.jit(agent.update_options)(states, batch, key)
    alone, a_metrics = jax.jit(each_option(agent.update))(states, batch, key)
    assert int(a_metrics["decisions"].sum()) > 20  # the options did have decisions
    assert_trees_close(grouped, alone, rtol=2e-4, atol=2e-6)
    assert g_metrics.keys() == a_metrics.keys()
    for name in a_metrics:
        np.testing.assert_allclose(np.asarray(g_metrics[name]), np.asarray(a_metrics[name]),
                                   rtol=2e-4, atol=2e-6, err_msg=name)


def test_an_option_without_decisions_keeps_its_parameters():
    agent = make_agent("ppo", hidden_sizes=(16, 16))
    batch, _ = joint_batch(_pending(3), _record(3))
    states = _states(agent, 3)
    new, metrics = jax.jit(agent.update_options)(states, batch, jax.random.PRNGKey(0))
    idle = lambda tree: jax.tree.map(lambda x: np.asarray(x[IDLE]), tree)  # noqa: E731
    assert_trees_close(idle(new.params), idle(states.params), rtol=0, atol=0)
    assert_trees_close(idle(new.opt_state), idle(states.opt_state), rtol=0, atol=0)
    assert int(metrics["decisions"][IDLE]) == 0 and int(new.grad_steps[IDLE]) == 0
    busy = [o for o in range(O) if o != IDLE]
    assert (np.asarray(new.grad_steps)[busy] > 0).all()  # the others did step


def test_grouped_gradients_are_each_options_own():
    # the gradient of option o's loss over its rows 0 .. counts[o] - 1, whatever the block
    # size, and nothing for an option without rows
    k = jax.random.split(jax.random.PRNGKey(4), 3)
    params = {"w": jax.random.normal(k[0], (O, F, 3)), "b": jax.random.normal(k[1], (O, 3))}
    x = jax.random.normal(k[2], (O, 11, F))
    counts = jnp.asarray([11, 4, 0, 7], jnp.int32)

    def option_loss(p, rows, weight):
        return jnp.sum(weight * jnp.tanh(rows @ p["w"] + p["b"]).sum(-1))

    def block_loss(own, o, j, valid):
        loss = option_loss(own, x[o, jnp.minimum(j, 10)], valid.astype(jnp.float32))
        return loss, {"rows": valid.sum().astype(jnp.float32)}

    want = [jax.grad(option_loss)(jax.tree.map(lambda a: a[o], params), x[o],
                                  (jnp.arange(11) < counts[o]).astype(jnp.float32))
            for o in range(O)]
    want = jax.tree.map(lambda *g: jnp.stack(g), *want)
    for block, per_step in ((1, 1), (4, 1), (16, 1), (1, 3), (4, 8)):
        grads, sums = jax.jit(lambda p, c, b=block, k=per_step: grouped_grads(
            block_loss, p, c, b, k))(params, counts)
        assert_trees_close(grads, want, rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(np.asarray(sums["rows"]), np.asarray(counts))
    assert not np.asarray(grads["w"][2]).any()


def test_the_grouped_update_is_chosen_by_backend_unless_named():
    assert make_agent("ppo", option_update="grouped").update_options is not None
    assert make_agent("ppo", option_update="per_option").update_options is None
    assert make_agent("ppo").update_options is not None  # auto: grouped on every backend
    with pytest.raises(ValueError, match="option_update"):
        make_agent("ppo", option_update="sometimes")
    with pytest.raises(ValueError, match="option_blocks_per_step"):
        make_agent("ppo", option_blocks_per_step=-1)
    # blocks per pass: one on a CPU; on an accelerator those a minibatch's expected rows
    # fill, one partly filled block per option; or as named
    assert blocks_per_step(3, 1024, 128, 5) == 3
    assert blocks_per_step(0, 1024, 128, 5) == (1 if jax.default_backend() == "cpu" else 13)


@pytest.mark.parametrize("block,per_step", [(1, 1), (3, 1), (128, 1), (3, 4)])
def test_the_values_on_the_decisions_are_those_each_option_acts_with(block, per_step):
    # option_values gives each option's critic where that option decided (0 elsewhere,
    # and for an option that never decides), as its act gives them
    agent = make_agent("ppo", hidden_sizes=(16, 16), option_block=block,
                       option_blocks_per_step=per_step)
    traj, states = _record(block), _states(agent, block)
    values = jax.jit(agent.option_values)(states, traj.obs, traj.decision)
    chex.assert_shape(values, (T, B, O))
    chex.assert_tree_all_finite(values)
    masks = jnp.ones((B, A), bool)
    acted = jax.vmap(lambda t: jax.vmap(agent.act, (0, None, None, None))(
        states, traj.obs[t], masks, jax.random.PRNGKey(0)).value)(jnp.arange(T))  # [T, O, B]
    want = jnp.where(traj.decision, jnp.swapaxes(acted, 1, 2), 0.0)
    assert int(traj.decision.sum()) > 20 and not np.asarray(values[:, :, IDLE]).any()
    np.testing.assert_allclose(np.asarray(values), np.asarray(want), rtol=1e-5, atol=1e-6)


def test_only_a_critic_apart_from_the_actor_is_left_to_option_values():
    assert make_agent("ppo").option_values is not None
    for config in (dict(shared_torso=True), dict(torso="conv"), dict(recurrent_size=4),
                   dict(option_update="per_option")):
        assert make_agent("ppo", **config).option_values is None, config
    assert make_agent("actor-critic").option_values is None
