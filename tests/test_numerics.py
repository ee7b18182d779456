"""Non-finite learner parameters stop the run with a clear error and keep the last good
checkpoint. (TensorBoard event files: test_train.py::test_results_contract.)"""
import jax
import jax.numpy as jnp
import pytest

import smjax.agents as agents
from hier_env import KeyDoor, make_keydoor
from smjax.train import TrainConfig
from smjax.train import checkpoint as ckpt
from smjax.train.loop import NonFiniteError
from smjax.train.run import run

CFG = dict(num_envs=8, rollout_ticks=8, updates_per_chunk=1, max_episodes_per_level=400,
           success_window=32, gate_envs=8, eval_envs=8, checkpoint_every=0.0, finetune="off")


def test_nan_injection_stops_cleanly_and_keeps_last_good_checkpoint(tmp_path, monkeypatch):
    real = agents.make_agent

    def poisoned(algo, **kw):
        agent = real(algo, **kw)

        def update(state, traj, key):
            new, metrics = agent.update(state, traj, key)
            # after the third update of the first level the parameters go NaN
            bad = jax.tree.map(lambda p: jnp.where(new.updates >= 3, jnp.nan, p), new.params)
            return new.replace(params=bad), metrics

        return agent._replace(update=update)

    monkeypatch.setattr(agents, "make_agent", poisoned)
    out = tmp_path / "run"
    with pytest.raises(NonFiniteError, match=r"level 1 \(open_door\)"):
        run(make_keydoor(), TrainConfig(**CFG), [0], out, progress=False)
    info = ckpt.load_meta(out)
    assert info is not None and info["meta"]["host"]["chunks"] >= 1
    # the checkpoint on disk holds finite parameters only
    step_dir = out / "checkpoints" / info["path"]
    assert step_dir.exists()



class NanRewardKeyDoor(KeyDoor):
    """Every step pays NaN: the learner's parameters go non-finite."""

    def step_env(self, key, state, action, params):
        obs, state, reward, term, trunc, info = super().step_env(key, state, action, params)
        return obs, state, reward + jnp.nan, term, trunc, info


def test_a_nan_reward_is_named_as_the_cause():
    env = NanRewardKeyDoor()
    cfg = TrainConfig(**(CFG | {"method": "flat"}))
    with pytest.raises(NonFiniteError, match="returns non-finite rewards .*fix the reward") as err:
        run((env, env.default_params), cfg, [0], None, progress=False)
    assert "learning rate" not in str(err.value)
