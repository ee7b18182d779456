"""Scene builders shared by the football tests."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from smjax.envs.football import constants as C
from smjax.envs.football.rules import step_game
from smjax.envs.football.noise import draw_noise
from smjax.envs.football.reset import initial_state
from smjax.envs.football.types import FootballState


def parked_positions() -> np.ndarray:
    """Everybody out of the way: left team on its own goal line area, right team spread far left."""
    pos = np.zeros((22, 2), np.float32)
    ys = np.linspace(-0.35, 0.35, 11)
    pos[:11, 0], pos[:11, 1] = -0.95, ys
    pos[11:, 0], pos[11:, 1] = -0.75, ys
    return pos


def scene(pos: np.ndarray, owner: int = -1, ball=None, ball_vel=(0.0, 0.0, 0.0), mode: int = C.NORMAL,
          last_touch: int | None = None, sticky_dir=None) -> FootballState:
    """A normal-play state with the given positions; a carrier gets the ball at his feet."""
    s = initial_state(0)
    pos = jnp.asarray(pos, jnp.float32)
    facing = jnp.tile(jnp.array([[1.0, 0.0]]), (22, 1)).at[11:].set(jnp.array([-1.0, 0.0]))
    if ball is None:
        ball = (pos[owner, 0] + C.BALL_OFFSET, pos[owner, 1], 0.0) if owner >= 0 else (0.0, 0.0, 0.0)
    sticky = jnp.zeros((22,), jnp.int32) if sticky_dir is None else jnp.asarray(sticky_dir, jnp.int32)
    return s.replace(
        pos=pos, vel=jnp.zeros((22, 2)), facing=facing, sticky_dir=sticky,
        ball_pos=jnp.asarray(ball, jnp.float32), ball_vel=jnp.asarray(ball_vel, jnp.float32),
        owner=jnp.int32(owner), last_touch=jnp.int32(owner if last_touch is None else last_touch),
        game_mode=jnp.int32(mode), pass_receiver=jnp.int32(-1),
    )


def run(state: FootballState, first_actions, ticks: int, seed: int = 0, later_actions=None):
    """Step the rules ``ticks`` times (first tick ``first_actions``, then idle/``later_actions``)."""
    first = jnp.asarray(first_actions, jnp.int32)
    later = jnp.zeros((22,), jnp.int32) if later_actions is None else jnp.asarray(later_actions, jnp.int32)
    keys = jax.random.split(jax.random.PRNGKey(seed), ticks)

    def body(carry, inp):
        s, total = carry
        i, k = inp
        s, goals = step_game(s, jnp.where(i == 0, first, later), draw_noise(k))
        return (s, total + goals), (s.owner, s.game_mode)

    (s, total), trace = jax.lax.scan(body, (state, jnp.zeros((2,), jnp.int32)), (jnp.arange(ticks), keys))
    return s, total, trace


run_jit = jax.jit(run, static_argnums=(2,))


def test_scene_builder_places_ball_at_carrier():
    pos = parked_positions()
    pos[1] = (0.2, 0.1)
    s = scene(pos, owner=1)
    assert int(s.owner) == 1 and int(s.game_mode) == C.NORMAL
    np.testing.assert_allclose(np.asarray(s.ball_pos[:2]), [0.2 + C.BALL_OFFSET, 0.1], atol=1e-6)
