"""Football env contract: registry, spaces, observations, symmetry, determinism, vmap, render."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smjax
from smjax.envs.football import constants as C
from smjax.envs.football.builtin_ai import all_actions
from smjax.envs.football.match import ai_tick
from smjax.envs.football.observation import paper139, simple115
from smjax.envs.football.rules import step_game
from smjax.envs.football.mirror import mirror_actions, mirror_noise, mirror_state
from smjax.envs.football.noise import draw_noise
from smjax.envs.football.reset import initial_state
from test_football_scenes import parked_positions, scene


@jax.jit
def _warm_state(key, ticks):
    def body(s, k):
        return ai_tick(k, s, jnp.array([0.6, 0.95]))[0], None
    return jax.lax.scan(body, initial_state(0), jax.random.split(key, 300))[0]


@jax.jit
def _ai_step(state, key):
    noise = draw_noise(key)
    actions = all_actions(state, jnp.array([0.6, 0.6]), noise)
    return step_game(state.replace(ai_prev=actions), actions, noise)[0], actions, noise


@jax.jit
def _mirrored_step(state, actions, noise):
    mirrored_actions = mirror_actions(actions)
    return step_game(mirror_state(state).replace(ai_prev=mirrored_actions), mirrored_actions,
                     mirror_noise(noise))[0]


@jax.jit
def _mirrored_ai(state, noise):
    return all_actions(mirror_state(state), jnp.array([0.6, 0.6]), mirror_noise(noise))


@pytest.mark.parametrize("seed", [0, 1])
def test_mirroring_the_state_mirrors_the_play(seed):
    state = _warm_state(jax.random.PRNGKey(seed), 300)
    keys = jax.random.split(jax.random.PRNGKey(seed + 100), 25)
    for k in keys:
        nxt, actions, noise = _ai_step(state, k)
        # The AI sees the mirrored state as the other team saw the original.
        mirrored_ai = _mirrored_ai(state, noise)
        np.testing.assert_array_equal(np.asarray(mirrored_ai), np.asarray(mirror_actions(actions)))
        expect = mirror_state(nxt)
        got = _mirrored_step(state, actions, noise)
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(expect)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-5)
        state = nxt


def _rollout(env, params, key, ticks, actions):
    def body(carry, k):
        obs, s = carry
        obs, s, r, te, tr, info = env.step(k, s, actions, params)
        return (obs, s), (obs, r, info["score"], s)
    obs, s = env.reset(key, params)
    return jax.lax.scan(body, (obs, s), jax.random.split(key, ticks))


def test_same_key_same_match():
    env, params = smjax.make("football/11v11_medium")
    roll = jax.jit(lambda k: _rollout(env, params, k, 200, jnp.full((11,), 19)))
    a, b = roll(jax.random.PRNGKey(3)), roll(jax.random.PRNGKey(3))
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    c = roll(jax.random.PRNGKey(4))
    assert not np.array_equal(np.asarray(a[0][1].pos), np.asarray(c[0][1].pos))


def _assert_same_play(got, want):
    for x, y in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
        x, y = np.asarray(x), np.asarray(y)
        if np.issubdtype(y.dtype, np.floating):
            np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6)
        else:  # who owns the ball, scores, cooldowns, facings: the play itself
            np.testing.assert_array_equal(x, y)


def test_vmapped_batch_equals_unbatched():
    # Checked one tick at a time, from many different states: vmap changes XLA's fusion and
    # so float32 rounding (~1e-9), and football is chaotic, so over a long rollout such a
    # difference can grow until a tackle or pass goes the other way (seen with XLA's
    # optimizations off). What must hold is that a batched tick is the unbatched tick.
    env, params = smjax.make("football/11v11_hard", observation="paper")
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    acts = jax.random.randint(jax.random.PRNGKey(1), (3, 11), 0, 20)
    _, (_, _, _, states) = jax.jit(jax.vmap(lambda k, a: _rollout(env, params, k, 60, a)))(keys, acts)
    # 3 matches x 6 moments (kick-off to tick 50), each with its own key and actions
    starts = jax.tree.map(lambda x: x[:, ::10].reshape((18,) + x.shape[2:]), states)
    tick_keys = jax.random.split(jax.random.PRNGKey(2), 18)
    tick_acts = jax.random.randint(jax.random.PRNGKey(3), (18, 11), 0, 20)
    step = lambda k, s, a: env.step(k, s, a, params)
    batched = jax.jit(jax.vmap(step))(tick_keys, starts, tick_acts)
    single = jax.jit(step)
    for i in range(18):
        _assert_same_play(jax.tree.map(lambda x: x[i], batched),
                          single(tick_keys[i], jax.tree.map(lambda x: x[i], starts), tick_acts[i]))
    owners = np.asarray(starts.owner)
    assert len(np.unique(owners)) > 2  # the moments really differ: several players had the ball


def test_registry_spaces_and_overrides():
    names = smjax.registry()
    for level in ("easy", "medium", "hard"):
        assert f"football/11v11_{level}" in names
    env, params = smjax.make("football/11v11_easy")
    assert float(params.difficulty) == pytest.approx(0.05)
    assert env.action_space(params).n == 20 and env.action_space(params).shape == (11,)
    assert env.primitive_action_names == ()
    assert env.observation_space(params).shape == (115,)
    env2, params2 = smjax.make("football/11v11_easy", observation="paper", game_length=50,
                               checkpoint_reward=True, difficulty=0.3)
    assert env2.observation_space(params2).shape == (139,) and env2.game_length == 50
    assert float(params2.difficulty) == pytest.approx(0.3) and bool(params2.checkpoint_reward)
    with pytest.raises(ValueError, match="simple115"):
        smjax.make("football/11v11_easy", observation="pixels")
    with pytest.raises(ValueError, match="difficulty"):
        smjax.make("football/11v11_easy", difficulty=2.0)
    with pytest.raises(TypeError, match="valid overrides"):
        smjax.make("football/11v11_easy", colour="red")


def test_observation_layouts():
    pos = parked_positions()
    pos[4] = (0.1, -0.2)
    pos[17] = (0.3, 0.25)
    s = scene(pos, owner=17).replace(score=jnp.array([2, 1]), game_mode=jnp.int32(C.CORNER))
    o = np.asarray(simple115(s))
    assert o.shape == (115,) and np.all(np.isfinite(o))
    np.testing.assert_allclose(o[8:10], [0.1, -0.2])
    np.testing.assert_allclose(o[44 + 12:44 + 14], [0.3, 0.25])
    np.testing.assert_allclose(o[94:97], [0, 0, 1])
    assert o[97:108].sum() == 1 and o[108 + C.CORNER] == 1
    p = np.asarray(paper139(s))
    assert p.shape == (139,)
    np.testing.assert_allclose(p[22 + 12:22 + 14], [0.3, 0.25])
    np.testing.assert_allclose(p[88], 0.0)                 # GK role
    np.testing.assert_allclose(p[116:119], [0, 0, 1])
    assert p[119 + 6] == 1 and p[119:130].sum() == 1
    np.testing.assert_allclose(p[130:132], [2, 1])
    assert p[132 + C.CORNER] == 1


def test_reward_info_truncation_and_checkpoints():
    env, params = smjax.make("football/11v11_easy", game_length=30, checkpoint_reward=True)
    pos = parked_positions()
    pos[1] = (0.8, 0.0)
    pos[11] = (-0.9, 0.0)
    s = scene(pos, owner=1).replace(step=jnp.int32(0))
    acts = jnp.zeros((11,), jnp.int32).at[1].set(C.SHOT)
    total = 0.0
    step = jax.jit(env.step_env)
    for t in range(12):
        obs, s, r, term, trunc, info = step(jax.random.PRNGKey(t), s, acts, params)
        total += float(r)
        acts = jnp.zeros((11,), jnp.int32)
        if int(info["score"][0]) == 1:
            break
    assert int(info["goal_difference"]) == 1 and not bool(term)
    assert total == pytest.approx(1.0 + 1.0)              # the goal plus all 10 checkpoints
    assert not bool(trunc)
    obs, s2 = env.reset(jax.random.PRNGKey(0), params)
    s2 = s2.replace(step=jnp.int32(29))
    _, _, _, _, trunc, _ = step(jax.random.PRNGKey(0), s2, jnp.full((11,), 19), params)
    assert bool(trunc)


def test_auto_reset_at_game_end():
    env, params = smjax.make("football/11v11_hard", game_length=5)
    obs, s = env.reset(jax.random.PRNGKey(0), params)
    step = jax.jit(env.step)
    for t in range(5):
        obs, s, r, term, trunc, info = step(jax.random.PRNGKey(t), s, jnp.full((11,), 19), params)
    assert bool(trunc) and int(s.step) == 0 and info["final_observation"].shape == (115,)


def test_the_episode_cap_is_a_traced_max_steps_in_params():
    """Named as every smjax environment's cap: check_env shortens it to see episodes end
    (football's defaults never end one in its rollout), gymnax trainers read it."""
    from smjax.core.adapters import gymnax_params

    env, params = smjax.make("football/11v11_hard", game_length=40)
    assert int(params.max_steps) == 40
    assert gymnax_params(params).max_steps_in_episode == 40
    _, s = env.reset(jax.random.PRNGKey(0), params)
    step = jax.jit(env.step_env)  # one program for both caps: the cap is traced
    for cap, ends in ((3, True), (40, False)):
        _, _, _, _, trunc, _ = step(jax.random.PRNGKey(0), s.replace(step=jnp.int32(2)),
                                    jnp.full((11,), 19), params.replace(max_steps=cap))
        assert bool(trunc) == ends
    assert step._cache_size() == 1


def test_render_draws_an_image():
    env, params = smjax.make("football/11v11_medium")
    _, s = env.reset(jax.random.PRNGKey(0), params)
    img = env.render(s, params)
    assert img.shape == (232, 480, 3) and img.dtype == np.uint8
    colours = {tuple(c) for c in img.reshape(-1, 3)[::7]}
    assert (230, 60, 50) in colours and (60, 110, 240) in colours
    batched = jax.tree.map(lambda x: x[None], s)
    with pytest.raises(ValueError, match="unbatched"):
        env.render(batched, params)
