"""A recurrent option policy (``PPOConfig.recurrent_size``): the runner's per-option
memory, PPO's replay of it, and a task only memory solves."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from hier_env import make_keydoor
from smjax.agents import make_agent
from smjax.agents.networks import flatten_obs, masked_log_softmax, take_action
from smjax.agents.networks import RecurrentActorCritic
from smjax.agents.ppo import PPOConfig, unroll
from smjax.agents.smdp import carry_pending
from smjax.core import Environment, spaces
from smjax.options import declare
from smjax.options.runner import Controls, HierarchyRunner
from smjax.options.stack import stack_members
from smjax.train import TrainConfig
from smjax.train.run import run

MEMORY = 8


def _rollouts(learner: int, sharpen: float = 30.0, num_envs=16, ticks=24, rollouts=2):
    """Two consecutive rollouts of a recurrent PPO learner on KeyDoor's paper hierarchy
    (learner 0: the root, its template teleported; learner 1: give_key, called by a
    frozen root from the bank). The policy heads are scaled up so that the memory moves
    the logits visibly. Returns the agent, its params, and per rollout (the trajectory
    with the pending row prepended, every tick's carry)."""
    env, params = make_keydoor()
    h = env.hierarchies()["paper"]
    agent = make_agent("ppo", recurrent_size=MEMORY)
    obs, _ = env.reset_env(jax.random.PRNGKey(0), params)
    state = agent.init(jax.random.PRNGKey(1), obs, h.num_actions)
    p = state.params["params"]
    p["policy_head"]["kernel"] = p["policy_head"]["kernel"] * sharpen
    state = state.replace(params={"params": p})
    bank = jax.tree.map(lambda x: jnp.stack([x] * h.num_options), state.params)
    runner = HierarchyRunner(env, params, h, agent)
    learned = jnp.asarray([learner != 0, False])
    controls = Controls(jnp.asarray(learner), jnp.asarray(0), learned, gamma=0.9,
                        temperature=1.0, teleport=jnp.asarray(learner == 0),
                        continue_episodes=jnp.asarray(learner != 0))
    carry = runner.reset(jax.random.PRNGKey(2), controls, num_envs)

    @jax.jit
    def rollout(carry, key):
        def tick(c, k):
            c, tr, _ = runner.tick(c, k, state, bank, controls)
            return c, (tr, c)
        carry, (traj, carries) = jax.lax.scan(tick, carry, jax.random.split(key, ticks))
        traj, pending = carry_pending(carry.pending, traj)
        return carry.replace(pending=pending), traj, carries

    out = []
    for k in range(rollouts):
        carry, traj, carries = rollout(carry, jax.random.PRNGKey(10 + k))
        out.append((traj, carries))
    return agent, state.params, h, out


@pytest.mark.parametrize("learner", [0, 1])
def test_the_replay_gives_the_rollouts_own_log_probs(learner):
    agent, params, h, out = _rollouts(learner)
    network = agent_network(h.num_actions)
    for traj, _ in out:
        inputs = (flatten_obs(traj.obs, 2), traj.hidden, traj.decision.astype(bool),
                  traj.done.astype(bool))
        logits, _ = unroll(network, params, inputs)
        log_prob = take_action(masked_log_softmax(logits, traj.action_mask), traj.action)
        dec = np.asarray(traj.decision, bool)
        assert dec.sum() > 20
        np.testing.assert_allclose(np.asarray(log_prob)[dec], np.asarray(traj.log_prob)[dec],
                                   atol=1e-4)
        # the check can fail: without the recorded memory the replay differs
        blank = (inputs[0], jnp.zeros_like(traj.hidden), jnp.zeros_like(inputs[2]), inputs[3])
        logits0, _ = unroll(network, params, blank)
        lp0 = take_action(masked_log_softmax(logits0, traj.action_mask), traj.action)
        assert np.abs(np.asarray(lp0)[dec] - np.asarray(traj.log_prob)[dec]).max() > 1e-2


def agent_network(num_actions):
    return RecurrentActorCritic(num_actions, (64, 64), "tanh", MEMORY)


@pytest.mark.parametrize("learner", [0, 1])
def test_memory_is_zero_off_the_stack_and_at_each_runs_first_decision(learner):
    _, _, h, out = _rollouts(learner)
    for traj, carries in out:
        on = jax.vmap(jax.vmap(lambda s: stack_members(s, h.num_options)))(carries.stack)
        hidden = np.asarray(carries.hidden)                          # [T, B, O, H]
        assert np.all(hidden[~np.asarray(on)] == 0)
        assert np.abs(hidden[np.asarray(on)]).max() > 0              # and it does move
        # a decision right after the learner's episode ended starts from zero memory
        dec, done = np.asarray(traj.decision, bool), np.asarray(traj.done, bool)
        after_end = np.zeros_like(dec)
        after_end[1:] = done[:-1]
        first = dec & after_end
        assert first.sum() > 0
        assert np.all(np.asarray(traj.hidden)[first] == 0)


def test_recurrent_update_takes_no_step_off_the_rollouts_policy():
    """With the parameters that acted, the first minibatch's ratio is exactly 1."""
    _, params, _, out = _rollouts(0)
    agent = make_agent("ppo", recurrent_size=MEMORY, update_epochs=1,
                       num_minibatches=1)
    traj = out[0][0]
    state = agent.init(jax.random.PRNGKey(1), traj.obs[0, 0], traj.action_mask.shape[-1])
    state = state.replace(params=params)
    _, metrics = agent.update(state, traj, jax.random.PRNGKey(3))
    assert float(metrics["approx_kl"]) < 1e-7
    assert float(metrics["clip_fraction"]) == 0.0
    assert np.isfinite(float(metrics["value_loss"]))


# ---- a task only a policy with memory solves ----------------------------------------
@struct.dataclass
class RecallState:
    cue: jax.Array
    t: jax.Array


class Recall(Environment):
    """A cue (0 or 1) is shown on the first step only; after ``DELAY`` blank steps the
    agent must answer it (action = cue: reward 1, else 0; the episode ends). Without
    memory the answer is a coin flip (success 0.5 at best)."""

    name = "test/recall"
    DELAY = 2

    @property
    def default_params(self):
        return None

    def reset_env(self, key, params):
        state = RecallState(jax.random.bernoulli(key).astype(jnp.int32), jnp.asarray(0))
        return self.get_obs(state, params), state

    def step_env(self, key, state, action, params):
        new = state.replace(t=state.t + 1)
        asked = state.t == self.DELAY + 1
        reward = (asked & (action == state.cue)).astype(jnp.float32)
        return self.get_obs(new, params), new, reward, asked, jnp.asarray(False), {}

    def get_obs(self, state, params):
        shown = state.t == 0
        return jnp.stack([shown & (state.cue == 0), shown & (state.cue == 1),
                          state.t == self.DELAY + 1]).astype(jnp.float32)

    def action_space(self, params=None):
        return spaces.Discrete(2)

    def observation_space(self, params=None):
        return spaces.Box(0.0, 1.0, (3,))

    @property
    def primitive_action_names(self):
        return ("zero", "one")

    def hierarchies(self):
        return {"flat": declare(self, "recall", {"recall": ["primitives"]})}


def test_a_recurrent_policy_solves_what_a_memoryless_one_cannot():
    env = Recall()
    results = {}
    for size in (0, 16):
        cfg = TrainConfig(num_envs=32, rollout_ticks=16, updates_per_chunk=4,
                          max_episodes_per_level=6000, success_window=128, gate_envs=256,
                          eval_envs=256, finetune="off", threshold=0.9,
                          agent={"recurrent_size": size, "learning_rate": 3e-3})
        results[size] = np.mean(run((env, None), cfg, [0], progress=False)["final_success"])
    assert results[0] < 0.7, results
    assert results[16] > 0.9, results


def test_bad_recurrent_settings_are_refused():
    with pytest.raises(ValueError, match="recurrent_size"):
        PPOConfig(recurrent_size=-1)
    with pytest.raises(ValueError, match="recurrent_size"):
        PPOConfig(recurrent_size=True)
    with pytest.raises(ValueError, match="shared_torso"):
        PPOConfig(recurrent_size=8, shared_torso=True)
    with pytest.raises(ValueError, match="unknown DQNConfig field.*recurrent_size"):
        make_agent("dqn", recurrent_size=8)  # memory is PPO's alone
