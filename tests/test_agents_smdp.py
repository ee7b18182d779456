"""SMDP returns and transitions against plain-Python references written forwards."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smjax.agents.base import Transition
from smjax.agents.smdp import (
    carry_pending, complete_decisions, episodes_with_decision, no_pending, smdp_gae, smdp_transitions,
)

GAMMA = 0.9
# per-tick discounts: ordinary ticks and ticks where a template was teleported (gamma**d)
DISCOUNTS = (GAMMA, GAMMA, GAMMA, GAMMA**5, GAMMA**25)


def follow_decision(t, reward, discount, done, decision):
    """Walk forwards from decision tick t to the next decision or episode end.

    Returns (R, D, kind, next_tick): kind is "terminal", "decision" (next_tick is its
    tick) or "rollout_end".
    """
    num_ticks = len(reward)
    smdp_reward, prod = 0.0, 1.0
    i = t
    while True:
        smdp_reward += prod * reward[i]
        prod *= discount[i]
        if done[i]:
            return smdp_reward, prod, "terminal", None
        if i + 1 == num_ticks:
            return smdp_reward, prod, "rollout_end", None
        if decision[i + 1]:
            return smdp_reward, prod, "decision", i + 1
        i += 1


def reference_gae(reward, discount, done, decision, value, lam, bootstrap=True):
    """Forward reference: decisions pending at the rollout end are not trained (0), and
    the decision before one bootstraps from its value (or 0) without chaining past it."""
    num_ticks, num_envs = reward.shape
    adv = np.zeros((num_ticks, num_envs))
    trained = np.zeros((num_ticks, num_envs), bool)
    for b in range(num_envs):
        cols = [x[:, b] for x in (reward, discount, done, decision)]
        for t in reversed(range(num_ticks)):
            if not decision[t, b]:
                continue
            smdp_reward, prod, kind, nxt = follow_decision(t, *cols)
            if kind == "rollout_end":
                continue
            trained[t, b] = True
            if kind == "terminal":
                adv[t, b] = smdp_reward - value[t, b]
            elif trained[nxt, b]:
                delta = smdp_reward + prod * value[nxt, b] - value[t, b]
                adv[t, b] = delta + prod * lam * adv[nxt, b]
            else:  # the next decision is pending: truncate there
                adv[t, b] = smdp_reward + prod * (value[nxt, b] if bootstrap else 0.0) - value[t, b]
    returns = np.where(trained, adv + value, 0.0)
    return adv, returns, trained


@st.composite
def rollouts(draw):
    num_ticks = draw(st.integers(1, 14))
    num_envs = draw(st.integers(1, 3))
    size = num_ticks * num_envs
    floats = st.floats(-2.0, 2.0, allow_nan=False, width=32)

    def grid(strategy):
        return np.array(draw(st.lists(strategy, min_size=size, max_size=size))).reshape(num_ticks, num_envs)

    reward = grid(floats).astype(np.float32)
    discount = grid(st.sampled_from(DISCOUNTS)).astype(np.float32)
    done = grid(st.sampled_from([False] * 5 + [True]))
    decision = grid(st.sampled_from([False, True, True]))
    value = grid(floats).astype(np.float32)
    lam = draw(st.sampled_from([0.0, 0.5, 0.95, 1.0]))
    bootstrap = draw(st.booleans())
    return reward, discount, done, decision, value, lam, bootstrap


@settings(max_examples=60, deadline=None)
@given(rollouts())
def test_smdp_gae_matches_forward_reference(case):
    reward, discount, done, decision, value, lam, bootstrap = case
    adv, ret = smdp_gae(*map(jnp.asarray, (reward, discount, done, decision, value)), lam,
                        bootstrap=bootstrap)
    ref_adv, ref_ret, trained = reference_gae(reward, discount, done, decision, value, lam, bootstrap)
    np.testing.assert_allclose(np.asarray(adv), ref_adv, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(np.asarray(ret), ref_ret, rtol=1e-4, atol=1e-4)
    assert adv.shape == reward.shape and ret.shape == reward.shape
    assert np.all(np.asarray(adv)[~decision] == 0.0)
    np.testing.assert_array_equal(np.asarray(complete_decisions(done, decision)), trained)


def test_option_of_several_ticks_and_teleport_by_hand():
    # decision at 0 calls an option running ticks 0..2; decision at 3 is a teleport
    # (discount g**5); decision at 4 ends the episode; tick 5 precedes the next episode's
    # first decision (reward 0 by contract, but any reward there must not leak); decision
    # at 6 is pending at the rollout end: not trained, and nothing bootstraps from tick 7.
    g = GAMMA
    reward = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 100.0, 7.0], np.float32)[:, None]
    discount = np.array([g, g, g, g**5, g, g, g], np.float32)[:, None]
    done = np.array([0, 0, 0, 0, 1, 0, 0], bool)[:, None]
    decision = np.array([1, 0, 0, 1, 1, 0, 1], bool)[:, None]
    value = np.array([0.5, 9, 9, 0.25, 0.125, 9, 1.0], np.float32)[:, None]
    adv, ret = smdp_gae(*map(jnp.asarray, (reward, discount, done, decision, value)), 1.0)
    ret = np.asarray(ret)[:, 0]
    # lam = 1: Monte-Carlo SMDP returns
    ret4 = 5.0
    ret3 = 4.0 + g**5 * ret4
    ret0 = 1.0 + g * 2.0 + g * g * 3.0 + g**3 * ret3
    np.testing.assert_allclose(ret[[0, 3, 4]], [ret0, ret3, ret4], rtol=1e-5)
    np.testing.assert_allclose(ret[[1, 2, 5, 6]], 0.0)


def reference_transitions(reward, discount, done, decision, obs, mask):
    out = []
    num_ticks, num_envs = reward.shape
    for t in range(num_ticks):
        for b in range(num_envs):
            if not decision[t, b]:
                continue
            cols = [x[:, b] for x in (reward, discount, done, decision)]
            smdp_reward, prod, kind, nxt = follow_decision(t, *cols)
            if kind == "decision":
                next_obs, next_mask = obs[nxt, b], mask[nxt, b]
            else:
                next_obs, next_mask = None, None  # unused: terminal, or pending (not stored)
            out.append((t, b, smdp_reward, prod, kind == "terminal", next_obs, next_mask,
                        kind != "rollout_end"))
    return out


@settings(max_examples=40, deadline=None)
@given(rollouts(), st.integers(0, 2**31 - 1))
def test_smdp_transitions_match_reference(case, seed):
    reward, discount, done, decision, _, _, _ = case
    num_ticks, num_envs = reward.shape
    rng = np.random.default_rng(seed)
    obs = rng.integers(0, 255, (num_ticks, num_envs, 3), dtype=np.uint8)
    mask = rng.random((num_ticks, num_envs, 4)) < 0.6
    tr = smdp_transitions(*map(jnp.asarray, (reward, discount, done, decision, obs, mask)))
    tr = jax.tree.map(np.asarray, tr)
    expected_valid = np.zeros_like(decision)
    for t, b, smdp_reward, prod, terminal, next_obs, next_mask, complete in reference_transitions(
            reward, discount, done, decision, obs, mask):
        expected_valid[t, b] = complete
        if not complete:
            continue
        np.testing.assert_allclose(tr.reward[t, b], smdp_reward, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(tr.discount[t, b], prod, rtol=1e-4, atol=1e-7)
        assert tr.terminal[t, b] == terminal
        if not terminal:
            np.testing.assert_array_equal(tr.next_obs[t, b], next_obs)
            np.testing.assert_array_equal(tr.next_mask[t, b], next_mask)
    np.testing.assert_array_equal(tr.valid, expected_valid)
    assert tr.next_obs.dtype == np.uint8


def _random_transitions(case, seed):
    reward, discount, done, decision, value, _, _ = case
    rng = np.random.default_rng(seed)
    shape = reward.shape
    return Transition(
        obs=rng.integers(0, 255, shape + (3,), dtype=np.uint8),
        action=rng.integers(0, 4, shape).astype(np.int32),
        action_mask=rng.random(shape + (4,)) < 0.6,
        log_prob=rng.normal(size=shape).astype(np.float32), value=value,
        decision=decision, reward=reward, discount=discount, done=done)


# Jitted, as training runs them: op by op, every new rollout shape compiles each primitive
# (and each scan) separately, 4x slower here for the same values.
_carry_pending = jax.jit(carry_pending)
_smdp_transitions = jax.jit(smdp_transitions)


def _stored(traj: Transition) -> list:
    """The (obs, action, R, D, terminal, next_obs) of every complete decision, per env."""
    tr = jax.tree.map(np.asarray, _smdp_transitions(traj.reward, traj.discount, traj.done,
                                                    traj.decision, traj.obs, traj.action_mask))
    rows = []
    for t, b in zip(*np.nonzero(tr.valid)):
        rows.append((int(b), tuple(np.asarray(traj.obs)[t, b]), int(np.asarray(traj.action)[t, b]),
                     float(tr.reward[t, b]), float(tr.discount[t, b]), bool(tr.terminal[t, b]),
                     None if tr.terminal[t, b] else tuple(tr.next_obs[t, b])))
    return rows


@settings(max_examples=40, deadline=None)
@given(rollouts(), st.integers(0, 2**31 - 1), st.lists(st.integers(1, 13), max_size=4))
def test_carried_decisions_give_the_targets_of_one_long_rollout(case, seed, cuts):
    """Cutting a rollout anywhere and carrying the pending decisions across the cuts
    trains exactly the decisions, with exactly the targets, of the uncut rollout."""
    traj = _random_transitions(case, seed)
    num_ticks, num_envs = traj.reward.shape
    bounds = [0] + sorted({c for c in cuts if c < num_ticks}) + [num_ticks]
    pending = no_pending(jnp.asarray(traj.obs[0]), 4)
    pieces = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        part = jax.tree.map(lambda x: jnp.asarray(x[lo:hi]), traj)
        extended, pending = _carry_pending(pending, part)
        assert extended.reward.shape == (hi - lo + 1, num_envs)
        pieces += _stored(extended)
    whole, _ = _carry_pending(no_pending(jnp.asarray(traj.obs[0]), 4),
                              jax.tree.map(jnp.asarray, traj))
    expected = sorted(_stored(whole), key=repr)
    got = sorted(pieces, key=repr)
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        assert a[:3] == b[:3] and a[5:] == b[5:]
        np.testing.assert_allclose(a[3:5], b[3:5], rtol=1e-5, atol=1e-6)
    # what is still pending is what the uncut rollout leaves incomplete
    incomplete = np.asarray(traj.decision) & ~np.asarray(complete_decisions(traj.done, traj.decision))
    np.testing.assert_array_equal(np.asarray(pending.decision), incomplete.any(0))


@settings(max_examples=40, deadline=None)
@given(rollouts())
def test_episodes_with_decision_matches_reference(case):
    _, _, done, decision, _, _, _ = case
    expected = 0
    for b in range(done.shape[1]):
        decided = True  # the first segment continues an episode from an earlier rollout
        for t in range(done.shape[0]):
            decided = decided or bool(decision[t, b])
            if done[t, b]:
                expected += int(decided)
                decided = False
    assert int(episodes_with_decision(jnp.asarray(done), jnp.asarray(decision))) == expected


def test_smdp_gae_jits_and_vmaps_over_seeds():
    key = jax.random.PRNGKey(0)
    shape = (3, 6, 2)  # seeds x T x B
    reward = jax.random.normal(key, shape)
    discount = jnp.full(shape, GAMMA)
    done = jax.random.bernoulli(jax.random.PRNGKey(1), 0.2, shape)
    decision = jax.random.bernoulli(jax.random.PRNGKey(2), 0.6, shape)
    value = jax.random.normal(jax.random.PRNGKey(3), shape)
    batched = jax.jit(jax.vmap(smdp_gae, in_axes=(0, 0, 0, 0, 0, None)))(
        reward, discount, done, decision, value, 0.95)
    for i in range(3):
        single = smdp_gae(reward[i], discount[i], done[i], decision[i], value[i], 0.95)
        np.testing.assert_allclose(batched[0][i], single[0], rtol=1e-5, atol=1e-6)


if __name__ == "__main__":
    pytest.main([__file__, "-q"])
