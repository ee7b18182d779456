"""Seeds train their levels at their own pace: a seed's numbers are those it gets alone."""
from hier_env import make_keydoor
from smjax.train import TrainConfig
from smjax.train.run import run

CFG = TrainConfig(num_envs=16, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=1500,
                  success_window=64, gate_envs=32, eval_envs=32,
                  finetune_max_episodes=96, finetune_turn_episodes=48)


def _seed_view(res: dict, s: int) -> dict:
    levels = [{k: (v[s] if isinstance(v, list) else v) for k, v in lvl.items()}
              for lvl in res["levels"]]
    return {"levels": levels, "final": res["final_success"][s],
            "episodes": res["episodes_to_threshold"][s]}


def test_each_seed_equals_that_seed_trained_alone():
    together = run(make_keydoor(), CFG, [0, 3], progress=False)
    # the seeds finished their first level at different times: one did not wait for the other
    first = together["levels"][0]["env_steps"]
    assert first[0] != first[1]
    alone = run(make_keydoor(), CFG, [3], progress=False)
    assert _seed_view(together, 1) == _seed_view(alone, 0)
