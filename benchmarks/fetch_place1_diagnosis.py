"""Why Fetch's place_1 level does not learn (before levels were gated).

    JAX_PLATFORMS=cpu python benchmarks/fetch_place1_diagnosis.py      # ~15 min on 2 CPU cores

Trains stack3 top-down for 1 seed (root and place_0 as the benchmark does, place_1/place_2
skipped), then runs the frozen root + learned place_0 with a fresh (epsilon 1) place_1
learner and reports, at each episode's first place_1 call, whether block 0 is in place;
and the final score of root + learned place_0 with place_1/place_2 scripted.
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import smjax  # noqa: E402  (XLA:CPU workaround before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import fetch_sample_complexity as fsc  # noqa: E402
from smjax.agents import make_agent  # noqa: E402
from smjax.envs.fetch import types as fetch_types  # noqa: E402
from smjax.envs.fetch.dynamics import blocks_placed  # noqa: E402
from smjax.options.runner import Controls  # noqa: E402
from smjax.train.engine import Engine  # noqa: E402
from smjax.train.run import run  # noqa: E402

NUM_ENVS, TICKS = 64, 1500


def train_root_and_place_0():
    args = argparse.Namespace(max_steps=60_000, flat_max_steps=1, rollout_ticks=16, algo="dqn",
                              num_envs=16, threshold=0.85, gamma=fsc.GAMMA, set=None,
                              hierarchy="paper_hold")
    cfg = fsc.level_config(3, "top-down", args, dict(fsc.AGENT))
    skip = {"max_steps_per_level": 1}
    cfg = cfg.replace(levels={"place_1": skip, "place_2": skip}, success_window=64)
    res = run("fetch/stack3", cfg, [0], None, env_overrides={"obs_include_goals": True},
              progress=False)
    for level in res["_raw"]["levels"]:
        print(level["template"], level["env_steps"], level["reached"],
              level["final_running_success"], flush=True)
    return cfg, res["_raw"]


def main() -> None:
    cfg, raw = train_root_and_place_0()
    env, params = smjax.make("fetch/stack3", obs_include_goals=True)
    h = env.hierarchies()["paper_hold"]
    agent = make_agent("dqn", **cfg.agent)
    engine = Engine(env, params, h, agent, cfg)
    ids = {name: i for i, name in enumerate(h.option_names)}
    learned = np.asarray(raw["learned"]).copy()              # [1 seed, options]
    learned[:, [ids["place_1"], ids["place_2"]]] = False
    learned = jnp.asarray(learned)
    bank = jax.tree.map(lambda x: x[0], raw["bank"])
    fresh = engine.init_learner(jax.random.split(jax.random.PRNGKey(1), 1))

    # A fresh place_1 learner under the frozen root and learned place_0.
    controls = Controls(jnp.asarray(ids["place_1"]), jnp.asarray(0), learned[0],
                        gamma=engine.gamma, temperature=engine.temperature)
    learner = jax.tree.map(lambda x: x[0], fresh)
    tick = jax.jit(lambda c, k: engine.runner.tick(c, k, learner, bank, controls))
    carry = engine.runner.reset(jax.random.PRNGKey(2), controls, NUM_ENVS)
    first_calls = block0_placed = finished = 0
    success, grip_to_goal1 = 0.0, []
    for key in jax.random.split(jax.random.PRNGKey(3), TICKS):
        started, before = np.asarray(carry.learner_started), carry.env_state
        carry, tr, ends = tick(carry, key)
        first = np.asarray(tr.decision) & ~started
        if first.any():
            placed = np.asarray(jax.vmap(lambda s: blocks_placed(s, params))(before))
            first_calls += int(first.sum())
            block0_placed += int((first & placed[:, 0]).sum())
            grip = np.asarray(jax.vmap(fetch_types.gripper_pos)(before))
            grip_to_goal1 += list(np.linalg.norm(grip - np.asarray(before.goals)[:, 1], axis=-1)[first])
        done = np.asarray(ends.finished)
        finished += int(done.sum())
        success += float(np.asarray(ends.success)[done].sum())
    median = np.median(grip_to_goal1) if grip_to_goal1 else float("nan")
    print(f"place_1 first calls {first_calls}, block 0 in place at {block0_placed}; median grip to "
          f"goal 1 {median:.3f} m; random place_1 success "
          f"{success / max(finished, 1):.3f} over {finished} episodes", flush=True)

    # The whole hierarchy: root + learned place_0, place_1/place_2 scripted.
    out, _ = engine.evaluate(jax.random.split(jax.random.PRNGKey(4), 1), raw["bank"], learned, fresh)
    print("root + learned place_0, scripted place_1/2:", {k: float(v[0]) for k, v in out.items()})


if __name__ == "__main__":
    main()
