"""Football rules: goals, kick-offs, restarts, shots, passes, tackles, directions."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings, strategies as st

from smjax.envs.football import constants as C
from smjax.envs.football.builtin_ai import quantize_direction
from smjax.envs.football.rules import step_game
from smjax.envs.football.noise import draw_noise
from smjax.envs.football.reset import initial_state, kickoff_positions
from test_football_scenes import parked_positions, run_jit, scene

IDLE22 = np.zeros(22, np.int32)


def _act(**by_player):
    a = IDLE22.copy()
    for k, v in by_player.items():
        a[int(k[1:])] = v
    return a


def test_goal_counts_and_conceding_team_kicks_off():
    s = scene(parked_positions(), owner=-1, ball=(0.99, 0.01, 0.0), ball_vel=(0.03, 0.0, 0.0), last_touch=1)
    s2, goals, _ = run_jit(s, IDLE22, 1)
    assert goals.tolist() == [1, 0] and s2.score.tolist() == [1, 0]
    assert int(s2.game_mode) == C.KICK_OFF
    assert int(s2.owner) == 12            # right team's centre player restarts
    expect = np.asarray(kickoff_positions(1)).copy()
    expect[12] = (C.BALL_OFFSET, 0.0)     # the taker stands behind the ball, facing left
    np.testing.assert_allclose(np.asarray(s2.pos), expect, atol=1e-6)
    np.testing.assert_allclose(np.asarray(s2.ball_pos), 0.0, atol=1e-6)


def test_ball_over_the_crossbar_is_no_goal():
    s = scene(parked_positions(), owner=-1, ball=(0.99, 0.0, 0.2), ball_vel=(0.03, 0.0, 0.0), last_touch=1)
    s2, goals, _ = run_jit(s, IDLE22, 1)
    assert goals.tolist() == [0, 0] and int(s2.game_mode) == C.GOAL_KICK
    assert int(s2.owner) == 11            # the right goalkeeper takes it


@given(x=st.floats(-0.9, 0.9), side=st.sampled_from([-1.0, 1.0]), toucher=st.integers(0, 21))
@settings(max_examples=15, deadline=None)
def test_ball_over_side_line_is_a_throw_in_for_the_other_team(x, side, toucher):
    s = scene(parked_positions(), owner=-1, ball=(x, side * 0.415, 0.0), ball_vel=(0.0, side * 0.02, 0.0),
              last_touch=toucher)
    s2, _, _ = run_jit(s, IDLE22, 1)
    assert int(s2.game_mode) == C.THROW_IN
    assert int(s2.owner) // 11 == 1 - toucher // 11
    np.testing.assert_allclose(float(s2.ball_pos[1]), side * 0.415, atol=1e-6)


@given(end=st.sampled_from([-1.0, 1.0]), y=st.floats(0.06, 0.4), toucher=st.integers(0, 21))
@settings(max_examples=15, deadline=None)
def test_ball_over_goal_line_is_corner_or_goal_kick(end, y, toucher):
    s = scene(parked_positions(), owner=-1, ball=(end * 0.995, y, 0.0), ball_vel=(end * 0.02, 0.0, 0.0),
              last_touch=toucher)
    s2, goals, _ = run_jit(s, IDLE22, 1)
    defender = 1 if end > 0 else 0
    assert goals.tolist() == [0, 0]
    if toucher // 11 == defender:
        assert int(s2.game_mode) == C.CORNER and int(s2.owner) // 11 == 1 - defender
    else:
        assert int(s2.game_mode) == C.GOAL_KICK and int(s2.owner) == 11 * defender


def test_restart_keeps_opponents_away_and_ends_on_kick():
    pos = parked_positions()
    pos[14] = (0.35, 0.36)              # inside the clearance radius of the throw-in spot
    s = scene(pos, owner=-1, ball=(0.3, 0.415, 0.0), ball_vel=(0.0, 0.02, 0.0), last_touch=14)
    s2, _, _ = run_jit(s, IDLE22, 1)
    taker = int(s2.owner)
    assert int(s2.game_mode) == C.THROW_IN and taker < 11
    d = np.linalg.norm(np.asarray(s2.pos[11:]) - np.asarray(s2.ball_pos[:2]), axis=1)
    assert d.min() >= C.RESTART_CLEARANCE - 1e-5
    kick = IDLE22.copy()
    kick[taker] = C.SHORT_PASS
    s3, _, _ = run_jit(s2, kick, 1)
    assert int(s3.game_mode) == C.NORMAL and int(s3.owner) != taker


@given(y=st.floats(-0.1, 0.1), seed=st.integers(0, 10_000))
@settings(max_examples=20, deadline=None)
def test_close_range_shot_at_empty_goal_scores(y, seed):
    pos = parked_positions()
    pos[1] = (0.88, y)
    pos[11] = (-0.9, 0.0)               # the goalkeeper is away
    s = scene(pos, owner=1)
    s2, goals, _ = run_jit(s, _act(p1=C.SHOT), 10, seed)
    assert goals.tolist() == [1, 0]


@given(angle=st.floats(-np.pi, np.pi), dist=st.floats(0.12, 0.5),
       kind=st.sampled_from([C.SHORT_PASS, C.LONG_PASS, C.HIGH_PASS]), seed=st.integers(0, 10_000))
@settings(max_examples=25, deadline=None)
def test_pass_reaches_a_free_teammate(angle, dist, kind, seed):
    pos = parked_positions()
    pos[11:, 0] = -0.98                   # opponents far away
    pos[1] = (0.0, 0.0)
    mate = np.array([np.cos(angle), np.sin(angle)]) * dist
    mate[1] = np.clip(mate[1], -0.38, 0.38)
    pos[5] = mate
    pos[[2, 3, 4, 6, 7, 8, 9, 10], 0] = -0.9    # other teammates well behind
    pos[[2, 3, 4, 6, 7, 8, 9, 10], 1] = np.linspace(-0.38, 0.38, 8)
    aim = int(quantize_direction(jnp.asarray(mate)))
    sticky = np.zeros(22, np.int32)
    sticky[1] = aim
    s = scene(pos, owner=1, sticky_dir=sticky)
    later = IDLE22.copy()
    later[1] = C.RELEASE_DIRECTION
    s2, _, (owners, _) = run_jit(s, _act(p1=kind), 80, seed, later)
    assert 5 in np.asarray(owners).tolist(), f"pass never reached the teammate; owners {np.asarray(owners)}"


@given(seed=st.integers(0, 100_000))
@settings(max_examples=30, deadline=None)
def test_sliding_tackle_wins_the_ball_or_gives_a_free_kick(seed):
    pos = parked_positions()
    pos[1] = (0.0, 0.0)
    pos[12] = (0.03, 0.0)                 # faces left, toward the carrier
    s = scene(pos, owner=1)
    s2, _, _ = run_jit(s, _act(p12=C.SLIDING), 1, seed)
    won = int(s2.owner) == 12
    foul = int(s2.game_mode) == C.FREE_KICK and int(s2.owner) < 11
    assert won != foul


def test_standing_tackles_change_possession_at_about_the_right_rate():
    pos = parked_positions()
    pos[1] = (0.0, 0.0)
    pos[12] = (0.02, 0.0)
    s = scene(pos, owner=1)
    owners = [int(run_jit(s, IDLE22, 1, seed)[0].owner) for seed in range(200)]
    rate = np.mean([o == 12 for o in owners])
    assert set(owners) <= {1, 12}
    assert 0.04 < rate < 0.2, rate       # STANDING_TACKLE_PROB = 0.1 per tick


def test_top_moves_toward_smaller_y_and_bottom_toward_larger_y():
    pos = parked_positions()
    pos[3] = (0.0, 0.0)
    s = scene(pos, owner=-1, ball=(0.5, 0.3, 0.0))
    up, _, _ = run_jit(s, _act(p3=C.TOP), 10)
    down, _, _ = run_jit(s, _act(p3=C.BOTTOM), 10)
    right, _, _ = run_jit(s, _act(p3=C.RIGHT), 10)
    assert float(up.pos[3, 1]) < -0.03 and abs(float(up.pos[3, 0])) < 1e-6
    assert float(down.pos[3, 1]) > 0.03
    assert float(right.pos[3, 0]) > 0.03
    assert int(quantize_direction(jnp.array([0.0, -1.0]))) == C.TOP


def test_sprint_is_faster_and_release_direction_stops():
    pos = parked_positions()
    pos[3] = (0.0, 0.0)
    s = scene(pos, owner=-1, ball=(0.5, 0.3, 0.0))
    sticky = np.zeros(22, np.int32)
    sticky[3] = C.RIGHT
    s = s.replace(sticky_dir=jnp.asarray(sticky))
    run_, _, _ = run_jit(s, IDLE22, 20)
    sprint, _, _ = run_jit(s, _act(p3=C.SPRINT), 20)
    stop, _, _ = run_jit(s, _act(p3=C.RELEASE_DIRECTION), 20)
    assert float(sprint.pos[3, 0]) > float(run_.pos[3, 0]) > 0.1
    assert float(stop.pos[3, 0]) < 0.01


def _random_play(seed: int, ticks: int):
    def body(s, k):
        ka, kn = jax.random.split(k)
        actions = jax.random.randint(ka, (22,), 0, 19)
        s2, goals = step_game(s, actions, draw_noise(kn))
        return s2, (s2, goals)

    return jax.lax.scan(body, initial_state(0), jax.random.split(jax.random.PRNGKey(seed), ticks))[1]


_random_play_jit = jax.jit(_random_play, static_argnums=1)


@given(seed=st.integers(0, 2**31 - 1))
@settings(max_examples=10, deadline=None)
def test_invariants_hold_under_random_play(seed):
    states, goals = _random_play_jit(seed, 300)
    pos, owner = np.asarray(states.pos), np.asarray(states.owner)
    ball = np.asarray(states.ball_pos)
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(ball))
    assert np.all(np.abs(pos[..., 0]) <= C.PLAYER_BOUND_X + 1e-6)
    assert np.all(np.abs(pos[..., 1]) <= C.PLAYER_BOUND_Y + 1e-6)
    assert np.all(ball[:, 2] >= 0.0) and np.all((owner >= -1) & (owner < 22))
    assert np.all((np.asarray(states.game_mode) >= 0) & (np.asarray(states.game_mode) < 7))
    held = owner >= 0
    carrier_pos = pos[np.arange(len(owner)), np.maximum(owner, 0)]
    gap = np.linalg.norm(ball[:, :2] - carrier_pos, axis=1)
    assert np.all(gap[held] <= C.BALL_OFFSET + 1e-5)   # a controlled ball is at his feet
    np.testing.assert_array_equal(np.asarray(states.score)[-1], np.asarray(goals).sum(0))
    # Only one of the two teams can score in a tick.
    assert np.all(np.asarray(goals).sum(1) <= 1)
