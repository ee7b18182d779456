"""The AI ladder script runs, and the difficulty param vmaps through the env."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from _helpers import load_benchmark


def _load_ladder():
    return load_benchmark("football_ai_ladder")


def test_ladder_table_shape_and_antisymmetric_bookkeeping():
    ladder = _load_ladder()
    result = ladder.ladder([0.05, 0.95], games=2, steps=40, seed=1)
    assert result["mean_goal_difference"].shape == (2, 2)
    assert result["ticks"] == 4 * 2 * 40
    table = ladder.to_markdown([0.05, 0.95], result)
    assert table.count("\n") == 3 and "| 0.95 |" in table
    with pytest.raises(ValueError, match="even"):
        ladder.ladder([0.05], games=3, steps=10)


def test_difficulty_is_a_traced_param_that_vmaps():
    env, params = smjax.make("football/11v11_medium", game_length=20)
    sweep = params.replace(difficulty=jnp.array([0.05, 0.6, 0.95]))
    _, state = env.reset(jax.random.PRNGKey(0), params)

    def run(p):
        def body(s, k):
            _, s, r, _, _, info = env.step_env(k, s, jnp.full((11,), 19), p)
            return s, s.pos
        return jax.lax.scan(body, state, jax.random.split(jax.random.PRNGKey(1), 20))[1]

    positions = jax.jit(jax.vmap(run, in_axes=(jax.tree.map(lambda _: 0, sweep)
                                               .replace(teammate_difficulty=None,
                                                        checkpoint_reward=None,
                                                        max_steps=None),)))(sweep)
    positions = np.asarray(positions)
    assert positions.shape == (3, 20, 22, 2)
    # Different opponent difficulty, different opponent play.
    assert not np.allclose(positions[0, :, 11:], positions[2, :, 11:])
