"""Fine-tuning with DQN on the test key-door room: per seed, final_success before the phase,
the fine-tuned hierarchy's check, which hierarchy the phase handed back (the better of the
two), and the final evaluation. Deterministic on a CPU.

    python benchmarks/finetune_keep_better_dqn.py --gradient-steps 16
    python benchmarks/finetune_keep_better_dqn.py --finetune-agent '{"epsilon_end": 0.2}'
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from hier_env import make_keydoor  # noqa: E402
from smjax.train import TrainConfig  # noqa: E402
from smjax.train.run import run  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gradient-steps", type=int, default=16, help="DQN gradient steps per update")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--finetune-agent", type=json.loads, default={}, metavar="JSON",
                    help="TrainConfig.finetune_agent: DQN hyper-parameters of the turns, e.g. "
                         "'{\"epsilon_end\": 0.2}'")
    args = ap.parse_args()
    agent = {"gradient_steps_per_update": args.gradient_steps}
    cfg = TrainConfig(algo="dqn", num_envs=32, rollout_ticks=16, updates_per_chunk=2,
                      max_episodes_per_level=3000, success_window=64, gate_envs=64, eval_envs=64,
                      finetune="on", finetune_max_episodes=1000, finetune_turn_episodes=250,
                      agent=agent, finetune_agent=args.finetune_agent)
    r = run(make_keydoor(), cfg, list(range(args.seeds)), progress=False)
    ft = r["finetune"]
    print(json.dumps({"agent": agent, "finetune_agent": args.finetune_agent, "levels": r["episodes_to_threshold"],
                      "before": ft["final_success_before"], "check": ft["check_success"],
                      "kept": ft["kept"], "final": r["final_success"]}))


if __name__ == "__main__":
    main()
