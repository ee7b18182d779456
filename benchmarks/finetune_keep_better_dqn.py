"""Fine-tuning with DQN on the test key-door room, 4 seeds: final_success before the phase,
the fine-tuned hierarchy's check, which one the phase handed back, and the final evaluation
(benchmarks/RESULTS.md section 13). Argument: DQN gradient steps per update.

    python benchmarks/finetune_keep_better_dqn.py 16
"""
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from hier_env import make_keydoor  # noqa: E402
from smjax.train import TrainConfig  # noqa: E402
from smjax.train.run import run  # noqa: E402

agent = {"gradient_steps_per_update": int(sys.argv[1])}
cfg = TrainConfig(algo="dqn", num_envs=32, rollout_ticks=16, updates_per_chunk=2, max_episodes_per_level=3000,
                  success_window=64, gate_envs=64, eval_envs=64, finetune="on", finetune_max_episodes=1000,
                  finetune_turn_episodes=250, agent=agent)
r = run(make_keydoor(), cfg, [0, 1, 2, 3], progress=False)
ft = r["finetune"]
print(json.dumps({"g": agent, "levels": r["episodes_to_threshold"], "before": ft["final_success_before"],
                  "check": ft["check_success"], "kept": ft["kept"], "final": r["final_success"]}))
