"""Football option templates: termination, initiation, directions, hierarchies, AI ladder."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from smjax.envs.football import constants as C
from smjax.envs.football.match import play_match
from test_football_scenes import parked_positions, scene

ENV, PARAMS = smjax.make("football/11v11_medium")
TPL = ENV.templates()
KEY = jax.random.PRNGKey(0)


def _sat(name, s):
    return bool(TPL[name].satisfied(s, PARAMS))


def _init(name, s):
    return bool(TPL[name].initiation(s, PARAMS))


def _ctrl(name, s):
    return np.asarray(TPL[name].controller(KEY, s, PARAMS))


def _carrying(x, y, player=1):
    pos = parked_positions()
    pos[player] = (x, y)
    return scene(pos, owner=player)


def test_all_templates_have_controllers_and_200_tick_timeouts():
    assert set(TPL) == {"attack", "defend", "maintain_possession", "charge", "shoot"}
    for t in TPL.values():
        assert t.k_max == 200 and t.controller is not None


def test_hierarchies_match_the_paper():
    h = ENV.hierarchies()
    assert h["paper"].children["win_game"] == ("attack", "defend")
    assert h["paper"].children["attack"] == ("maintain_possession", "charge", "shoot")
    assert "defend" not in h["paper"].children
    assert h["flat"].children["win_game"] == ("maintain_possession", "charge", "shoot", "defend")


def test_initiation_sets():
    ours, theirs = _carrying(0.0, 0.0), _carrying(0.0, 0.0, player=15)
    for name in ("attack", "maintain_possession", "charge", "shoot"):
        assert _init(name, ours) and not _init(name, theirs)
    assert _init("defend", theirs) and not _init("defend", ours)


def _failed(name, state):
    return bool(TPL[name].failed(state, PARAMS))


def test_attack_and_defend_termination():
    ours, theirs = _carrying(0.0, 0.0), _carrying(0.0, 0.0, player=15)
    # losing the ball ends the attack without its outcome (no reward for its learner)
    assert not _sat("attack", ours) and not _failed("attack", ours)
    assert not _sat("attack", theirs) and _failed("attack", theirs)
    assert _sat("defend", ours) and not _sat("defend", theirs)
    # Our pass in flight: still attacking, not yet defended.
    flying = ours.replace(owner=jnp.int32(-1), pass_receiver=jnp.int32(4))
    assert not _sat("attack", flying) and not _failed("attack", flying) and _sat("defend", flying)


def test_attack_is_satisfied_by_our_goal():
    # a shot from close range into the empty goal: the tick it goes in, attack is satisfied
    s = _carrying(0.9, 0.0)
    step = jax.jit(ENV.step_env)
    for i in range(30):
        _, s, reward, _, _, _ = step(jax.random.fold_in(KEY, i), s,
                                     TPL["shoot"].controller(KEY, s, PARAMS), PARAMS)
        if float(reward) > 0:
            break
    assert float(reward) == 1.0
    assert _sat("attack", s) and not _failed("attack", s)


def test_possession_charge_and_shoot_termination():
    assert not _sat("maintain_possession", _carrying(0.2, 0.0))
    assert _sat("maintain_possession", _carrying(0.55, 0.0))
    assert _failed("maintain_possession", _carrying(0.0, 0.0, player=15))
    assert not _sat("charge", _carrying(0.5, 0.0))
    assert _sat("charge", _carrying(0.75, 0.0))
    assert _failed("charge", _carrying(0.2, 0.0, player=15))
    assert not _sat("shoot", _carrying(0.8, 0.0))
    s = _carrying(0.8, 0.0)
    _, s2, _, _, _, _ = jax.jit(ENV.step_env)(KEY, s, TPL["shoot"].controller(KEY, s, PARAMS), PARAMS)
    assert int(s2.owner) == -1 and _sat("shoot", s2)


def test_charge_runs_toward_the_goal_with_correct_top_bottom():
    # Below the goal (y > 0 is the bottom of the screen) the carrier must run top-right.
    assert _ctrl("charge", _carrying(0.3, 0.35))[1] == C.TOP_RIGHT
    assert _ctrl("charge", _carrying(0.3, -0.35))[1] == C.BOTTOM_RIGHT
    s = _carrying(0.3, 0.0).replace(sticky_dir=jnp.zeros(22, jnp.int32).at[1].set(C.RIGHT))
    assert _ctrl("charge", s)[1] == C.SPRINT
    acts = _ctrl("charge", s)
    assert np.all(np.delete(acts, 1) == C.BUILTIN_AI)


def test_attack_picks_shoot_charge_or_possession_by_position():
    assert _ctrl("attack", _carrying(0.85, 0.05))[1] == C.SHOT
    assert _ctrl("attack", _carrying(0.55, 0.3))[1] == C.TOP_RIGHT
    free = _ctrl("attack", _carrying(0.0, 0.0))
    assert free[1] == C.RIGHT                 # nobody ahead: dribble straight at goal


def test_maintain_possession_passes_when_boxed_in():
    pos = parked_positions()
    pos[1] = (0.0, 0.0)
    for i, a in enumerate(np.linspace(-np.pi / 2, np.pi / 2, 6)):
        pos[12 + i] = (0.08 * np.cos(a), 0.08 * np.sin(a))   # a wall ahead
    pos[5] = (-0.3, 0.2)                                      # the only open teammate
    s = scene(pos, owner=1, sticky_dir=np.eye(22, dtype=np.int32)[1] * C.BOTTOM_LEFT)
    acts = _ctrl("maintain_possession", s)
    assert acts[1] in (C.SHORT_PASS, C.LONG_PASS, C.HIGH_PASS)
    # Two support runners, everyone else on the built-in AI.
    assert np.sum(acts != C.BUILTIN_AI) <= 3


def test_defend_hands_everything_to_the_builtin_ai():
    assert np.all(_ctrl("defend", _carrying(0.0, 0.0, player=15)) == C.BUILTIN_AI)


def test_controllers_jit_and_vmap():
    states = jax.tree.map(lambda *x: jnp.stack(x), _carrying(0.2, 0.1), _carrying(0.7, -0.2))
    for t in TPL.values():
        out = jax.jit(jax.vmap(lambda s: t.controller(KEY, s, PARAMS)))(states)
        assert out.shape == (2, 11) and out.dtype == jnp.int32
        assert jax.vmap(lambda s: t.satisfied(s, PARAMS))(states).shape == (2,)


@pytest.mark.slow
def test_harder_ai_beats_easier_ai_on_average():
    games, ticks = 32, 1500
    keys = jax.random.split(jax.random.PRNGKey(7), games)
    play = jax.jit(jax.vmap(play_match, in_axes=(0, None, None)), static_argnums=2)
    hard_left = play(keys, jnp.array([0.95, 0.05]), ticks)
    hard_right = play(keys, jnp.array([0.05, 0.95]), ticks)
    diff = np.concatenate([np.asarray(hard_left[:, 0] - hard_left[:, 1]),
                           np.asarray(hard_right[:, 1] - hard_right[:, 0])])
    assert diff.mean() > 1.0, diff
    medium = play(keys, jnp.array([0.6, 0.05]), ticks)
    assert np.mean(np.asarray(medium[:, 0] - medium[:, 1])) > 0.3
