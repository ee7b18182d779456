"""Why Fetch's place_1 level does not learn (benchmarks/RESULTS.md section 7.2).

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
import smjax  # noqa: E402,F401  (XLA:CPU workaround before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import fetch_sample_complexity as F  # noqa: E402
from smjax.train.run import run
from smjax.train.engine import Engine
from smjax.options.runner import Controls
from smjax.agents import make_agent
from smjax.envs.fetch.observation import blocks_placed
from smjax.envs.fetch import state as fst

args = argparse.Namespace(max_steps=60000, flat_max_steps=1, rollout_ticks=16, algo="dqn",
                          num_envs=16, threshold=0.85, gamma=F.GAMMA, set=None, hierarchy="paper_hold")
cfg = F.level_config(3, "top-down", args, dict(F.AGENT))
cfg = cfg.replace(levels={"place_1": {"max_steps_per_level": 1}, "place_2": {"max_steps_per_level": 1}},
                  success_window=64)
res = run("fetch/stack3", cfg, [0], None, env_overrides={"obs_include_goals": True}, progress=False)
raw = res["_raw"]
for lv in raw["levels"]:
    print(lv["template"], lv["env_steps"], lv["reached"], lv["final_running_success"], flush=True)
env, params = smjax.make("fetch/stack3", obs_include_goals=True)
h = env.hierarchies()["paper_hold"]
agent = make_agent("dqn", **cfg.agent)
eng = Engine(env, params, h, agent, cfg)
bank = jax.tree.map(lambda x: x[0], raw["bank"])
ids = {n: i for i, n in enumerate(h.option_names)}
learned = np.asarray(raw["learned"][0]).copy()
learned[ids["place_1"]] = False; learned[ids["place_2"]] = False
learned = jnp.asarray(learned)
B = 64
for label, learner_id in [("place_1 learner (random DQN init, eps=1)", ids["place_1"])]:
    controls = Controls(jnp.asarray(learner_id), jnp.asarray(0), learned)
    ls = agent.init(jax.random.PRNGKey(1), eng.example_obs, h.num_actions)
    carry = eng.runner.reset(jax.random.PRNGKey(2), controls, B)
    tick = jax.jit(lambda c, k: eng.runner.tick(c, k, ls, bank, controls))
    first_calls, b0_placed, grip_d, succ, fin, choices = 0, 0, [], 0.0, 0, np.zeros(h.num_actions, int)
    key = jax.random.PRNGKey(3)
    for t in range(1500):
        key, k = jax.random.split(key)
        started_before = np.asarray(carry.learner_started)
        st_before = carry.env_state
        carry, tr, ends = tick(carry, k)
        dec = np.asarray(tr.decision)
        first = dec & ~started_before
        if first.any():
            pl = np.asarray(jax.vmap(lambda s: blocks_placed(s, params))(st_before))
            first_calls += first.sum(); b0_placed += (first & pl[:, 0]).sum()
            gp = np.asarray(jax.vmap(fst.gripper_pos)(st_before)); goals = np.asarray(st_before.goals)
            grip_d += list(np.linalg.norm(gp - goals[:, 1], axis=-1)[first])
        for a in np.asarray(tr.action)[dec]: choices[a] += 1
        f = np.asarray(ends.finished); fin += f.sum(); succ += np.asarray(ends.success)[f].sum()
    print(label, "first calls", first_calls, "block0 placed at call", b0_placed,
          "grip->goal1 median", float(np.median(grip_d)) if grip_d else None,
          "episodes", fin, "success rate", succ / max(fin, 1),
          "choices", {h.option_names[a - h.num_primitives + 1] if a >= h.num_primitives else a: int(c) for a, c in enumerate(choices) if c}, flush=True)
# whole hierarchy, root+place_0 learned, place_1/2 scripted, no learner
out = jax.jit(lambda k: eng._evaluate(k, bank, learned, agent.init(jax.random.PRNGKey(1), eng.example_obs, h.num_actions)))(jax.random.PRNGKey(4))
print("eval root+place_0 learned, place_1/2 scripted:", {k: float(v) for k, v in out.items()})
