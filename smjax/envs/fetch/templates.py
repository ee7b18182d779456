"""Option templates and hierarchies of Fetch & Stack.

Level 1 (task ``stack``): ``place_i`` for every block i, plus ``noop``.
Level 2 (task ``place_i``): ``reach_i``, ``pick_i``, ``release_i``, plus ``noop``.
All templates are realised by the scripted controllers of ``controllers.py`` (the
environment cannot teleport). Termination tests (docs/environments.md, Fetch):

=============  =====================================================  =====  ==========
template       satisfied (F_o)                                        k_max  initiation
=============  =====================================================  =====  ==========
reach_i        ||block_i - grip|| < 0.03                               30    always
pick_i         ||block_i - goal_i|| < 0.03                             50    block i reached or held
release_i      grip z > goal_i z + 0.05                                30    block i within 0.04 of goal i
place_i        block i within 0.04 of goal i, not held, grip more     80    block i not in place
               than 0.08 from goal i ("released and clear")
noop           never (runs exactly one tick: k_max 1)                  1     always
hold           never (one tick, like noop)                             1     every block in place
=============  =====================================================  =====  ==========

``hold`` is the root's "do nothing" of the ``paper_hold`` hierarchy. A root that may do
nothing for one tick in any state has a near-free way to procrastinate: with a per-tick
gamma of 0.96 one tick of delay costs about 4 % of |Q|, within DQN's noise, so a learning
DQN root fills its buffer with noop decisions (dozens per episode) and idles. Holding is
only useful once the tower stands (keep it, gripper clear).
"""
from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from smjax.envs.fetch import controllers as ctl
from smjax.envs.fetch import types as st
from smjax.envs.fetch.dynamics import blocks_placed
from smjax.envs.fetch.policies import place_policy, stack_policy
from smjax.options import OptionTemplate, always, declare

K_MAX = {"place": 80, "reach": 30, "pick": 50, "release": 30, "noop": 1}
NOMINAL_STEPS = {"place": 40, "reach": 10, "pick": 20, "release": 6, "noop": 1}


# ---- termination and initiation tests (pure; i is a Python int) ----------------
def reach_satisfied(state, params, i: int) -> jax.Array:
    return ctl.is_reached(state, i)


def pick_satisfied(state, params, i: int) -> jax.Array:
    return ctl.block_to_goal(state, i) < ctl.PLACE_TOL


def release_satisfied(state, params, i: int) -> jax.Array:
    return st.gripper_pos(state)[2] > state.goals[i, 2] + ctl.RELEASE_HEIGHT


def place_satisfied(state, params, i: int) -> jax.Array:
    in_place = blocks_placed(state, params)[i]
    clear = jnp.linalg.norm(st.gripper_pos(state) - state.goals[i]) > params.clear_distance
    return in_place & ~ctl.is_gripping(state, i) & clear


def pick_initiation(state, params, i: int) -> jax.Array:
    return ctl.is_reached(state, i) | ctl.is_gripping(state, i)


def release_initiation(state, params, i: int) -> jax.Array:
    return blocks_placed(state, params)[i]


def place_initiation(state, params, i: int) -> jax.Array:
    return ~blocks_placed(state, params)[i]


def hold_initiation(state, params) -> jax.Array:
    return jnp.all(blocks_placed(state, params))


def never(state, params) -> jax.Array:
    return jnp.asarray(False)


def _controller(fn, i: int):
    def controller(key: jax.Array, state, params) -> jax.Array:
        return fn(state, params, i)

    return controller


def _noop_controller(key: jax.Array, state, params) -> jax.Array:
    return ctl.noop(state, params)


def make_templates(num_blocks: int) -> dict[str, OptionTemplate]:
    """name -> OptionTemplate for every block, plus ``noop``."""
    out: dict[str, OptionTemplate] = {}
    spec = {
        "place": (place_satisfied, place_initiation, ctl.place,
                  "reach, pick and release block {i} onto its goal (level 1)"),
        "reach": (reach_satisfied, None, ctl.reach, "open and move the grip point onto block {i}"),
        "pick": (pick_satisfied, pick_initiation, ctl.pick,
                 "close on block {i}, carry it above its goal and lower it"),
        "release": (release_satisfied, release_initiation, ctl.release,
                    "open the fingers and lift clear of block {i}"),
    }
    for i in range(num_blocks):
        for kind, (sat, init, fn, desc) in spec.items():
            name = f"{kind}_{i}"
            out[name] = OptionTemplate(
                name=name,
                satisfied=partial(sat, i=i),
                initiation=always if init is None else partial(init, i=i),
                k_max=K_MAX[kind],
                controller=_controller(fn, i),
                nominal_steps=NOMINAL_STEPS[kind],
                description=desc.format(i=i),
            )
    out["noop"] = OptionTemplate(
        name="noop", satisfied=never, k_max=K_MAX["noop"], controller=_noop_controller,
        nominal_steps=NOMINAL_STEPS["noop"], description="do nothing for one tick",
    )
    out["hold"] = OptionTemplate(
        name="hold", satisfied=never, initiation=hold_initiation, k_max=K_MAX["noop"],
        controller=_noop_controller, nominal_steps=NOMINAL_STEPS["noop"],
        description="do nothing for one tick, once every block is in place",
    )
    return out


def make_hierarchies(env) -> dict:
    """``paper``: stack -> place_i -> {reach_i, pick_i, release_i}; ``flat``: stack -> level 2.

    ``paper_hold``: ``paper`` with the root's ``noop`` replaced by ``hold`` (do nothing
    only once the tower stands; see the module docstring). Level 2 keeps ``noop``.
    ``paper_hold_all``: ``hold`` at level 2 as well, which leaves a ``place_i`` learner no
    do-nothing at all (``place_i`` runs only while block i is not in place).
    ``root_only``: ``paper_hold``'s root over scripted ``place_i`` leaves, so only the root
    learns (a quick way to study the root apart: a top-down run is one level).
    ``scripted``: ``paper`` with every decision scripted (``scripted_hierarchy``);
    ``scripted_root``: the root scripted over ``place_i`` leaves (their controllers).
    """
    n = env.num_blocks
    places = [f"place_{i}" for i in range(n)]
    paper = {"stack": places + ["noop"]}
    for i in range(n):
        paper[f"place_{i}"] = [f"reach_{i}", f"pick_{i}", f"release_{i}", "noop"]
    paper_hold = dict(paper, stack=places + ["hold"])
    paper_hold_all = {name: [("hold" if c == "noop" else c) for c in children]
                      for name, children in paper_hold.items()}
    declared = declare(env, "stack", paper)
    # flat: stack -> reach_i / pick_i / release_i for every block, then noop
    return {"paper": declared, "flat": declared.flattened(),
            "paper_hold": declare(env, "stack", paper_hold),
            "paper_hold_all": declare(env, "stack", paper_hold_all),
            "root_only": declare(env, "stack", {"stack": places + ["hold"]}),
            "scripted": scripted_hierarchy(env), "scripted_root": scripted_hierarchy(env, 1)}


def scripted_hierarchy(env, levels: int = 2, epsilon: float = 0.0):
    """The paper's hierarchy played by hand (``policies.py``): ``levels=2``: stack ->
    place_i -> reach_i / pick_i / release_i, every choice scripted; ``levels=1``: stack ->
    place_i, whose controllers act. ``epsilon``: the root explores (``stack_policy``)."""
    if levels not in (1, 2):
        raise ValueError(f"levels must be 1 or 2, got {levels!r}")
    n = env.num_blocks
    children = {"stack": [f"place_{i}" for i in range(n)] + ["noop"]}
    policies = {"stack": stack_policy(n, epsilon)}
    if levels == 2:
        for i in range(n):
            children[f"place_{i}"] = [f"reach_{i}", f"pick_{i}", f"release_{i}", "noop"]
            policies[f"place_{i}"] = place_policy
    return declare(env, "stack", children, policies=policies)
