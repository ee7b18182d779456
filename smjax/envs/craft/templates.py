"""Craft's option templates (``give_<item>``, ``give_<item>_x<n>``) and hierarchies (flat,
recipe, paper).

``give_X`` promises "X is held". Its teleport is the reference's: among the empty
4-neighbours of every cell holding X (a crafted X: of its workshop) pick one (stand cell,
facing) pair uniformly, stand there facing the target, for a crafted X add one X to the
inventory first, and return USE for the caller to execute in the same tick (so the call is
one environment step). With no such cell the state is returned unchanged with NOOP.
A stand cell next to two targets is two pairs, as in the reference's list of candidates.

Two additions of smjax's (docs/environments.md, Craft templates):

* ``give_X_xN`` promises "N of X are held" (initiable while fewer are). Multi-fire USE
  makes some recipes need two units of an ingredient (``recipe_plan.ingredient_counts``:
  a flag needs 2 sticks and 2 iron, since the axe recipe fires first and eats one of
  each), and ``give_X``, not initiable once one X is held, cannot fetch the second. Its
  teleport adds the missing units (all but the one its USE picks up, for a primitive).
* A treasure behind its barrier (gold in water, a gem in stone): the barrier cells next to
  it are stand cells too, and the teleport clears the one it stands in, which is where
  the learned ``give_gold`` ends (it crosses the water with a bridge). By the reference's
  rule the teleport would do nothing until the water is crossed, which would leave a
  task with gold as an ingredient (make_goldarrow) no way for its root to get the gold.
"""
from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.sampling import choose_uniform
from smjax.envs.craft import constants as C
from smjax.envs.craft.recipe_plan import BARRIER_OF_TREASURE, best_return, ingredient_counts
from smjax.envs.craft.types import CraftParams, CraftState
from smjax.options import Hierarchy, OptionTemplate, Parametric, declare

N = C.GRID_SIZE


def stand_candidates(grid: jax.Array, target_kind: int, barrier_kind=None) -> jax.Array:
    """bool [4, 12, 12]: standing at (x, y) facing direction d looks at a ``target_kind``
    cell, (x, y) being empty or (where given) of ``barrier_kind``."""
    target = grid == target_kind
    standable = grid == C.EMPTY
    if barrier_kind is not None:
        standable = standable | (grid == barrier_kind)
    pad = jnp.pad(target, 1)  # pad[x + 1, y + 1] == target[x, y]
    facing = []
    for dx, dy in C.DIRECTION_DELTAS:
        facing.append(jax.lax.slice(pad, (1 + dx, 1 + dy), (1 + dx + N, 1 + dy + N)))
    return jnp.stack(facing) & standable[None]


def _stand(key: jax.Array, state: CraftState, data: dict, barrier_kind=None):
    """A uniform (cell, facing) pair next to ``data``'s target: (cell, direction, possible)."""
    cand = stand_candidates(state.grid, data["target_kind"], barrier_kind).reshape(-1)
    index, count = choose_uniform(key, cand)
    return index % (N * N), index // (N * N), count > 0


def _jump(state: CraftState, data: dict, cell, direction, possible, grid=None):
    """``state`` standing at ``cell`` facing ``direction`` (where ``possible``), with the
    units of the promised count that the USE will not pick up added."""
    dtype = state.inventory.dtype
    held = state.inventory[data["item_id"]]
    # a primitive's USE picks one unit up; the rest of the promised count is added here
    missing = jnp.maximum(data["count"].astype(dtype) - held - data["picked"].astype(dtype), 0)
    return state.replace(
        grid=state.grid if grid is None else grid,
        pos=jnp.where(possible, jnp.stack([cell // N, cell % N]), state.pos).astype(jnp.int32),
        direction=jnp.where(possible, direction, state.direction).astype(jnp.int32),
        inventory=state.inventory.at[data["item_id"]].add(jnp.where(possible, missing, 0)),
    )


def give_teleport(key: jax.Array, state: CraftState, params: CraftParams, data: dict):
    """The teleport of every ``give_X`` but the treasures'; ``data`` says which X and how
    many (see ``teleport_data``).

    One function for the whole family (``Parametric``), so a batch in which different
    environments call different give_X templates evaluates it once, not once per X.
    """
    cell, direction, possible = _stand(key, state, data)
    action = jnp.where(possible, C.USE, C.NOOP).astype(jnp.int32)
    return _jump(state, data, cell, direction, possible), action


def treasure_teleport(key: jax.Array, state: CraftState, params: CraftParams, data: dict):
    """``give_gold`` / ``give_gem``: as ``give_teleport``, but a barrier cell next to the
    treasure is a stand cell too, and is cleared. A family of its own, so that only a
    hierarchy holding a treasure template (make_goldarrow's) pays for the grid write."""
    cell, direction, possible = _stand(key, state, data, data["barrier_kind"])
    flat = state.grid.reshape(-1)  # compare-and-select, as in dynamics (no scatter)
    grid = jnp.where((jnp.arange(N * N) == cell) & possible, jnp.uint8(C.EMPTY), flat)
    action = jnp.where(possible, C.USE, C.NOOP).astype(jnp.int32)
    return _jump(state, data, cell, direction, possible, grid.reshape(N, N)), action


def teleport_data(item: str, count: int = 1) -> dict:
    """Per-template data of the teleports: the item, the kind to stand next to, the count
    promised, the units the USE picks up (1 for a primitive) and, for a treasure, the
    barrier that may be cleared to stand there."""
    item_id = C.KIND_ID[item]
    data = {
        "item_id": np.int32(item_id),
        "target_kind": np.uint8(C.WORKSHOP_OF.get(item, item_id)),
        "count": np.int32(count),
        "picked": np.int32(item not in C.CRAFTED),
    }
    if item_id in BARRIER_OF_TREASURE:
        data["barrier_kind"] = np.uint8(BARRIER_OF_TREASURE[item_id])
    return data


def teleport_of(item: str, count: int = 1) -> Parametric:
    """The ``Parametric`` teleport of the template promising ``count`` of ``item``."""
    fn = treasure_teleport if C.KIND_ID[item] in BARRIER_OF_TREASURE else give_teleport
    return Parametric(fn, teleport_data(item, count))


def _held_fn(item_id: int, count: int, held: bool) -> Callable:
    def fn(state: CraftState, params: CraftParams) -> jax.Array:
        return (state.inventory[item_id] >= count) == held
    return fn


def counted_ingredients() -> tuple[tuple[str, int], ...]:
    """(item, count) of every ingredient some recipe needs more than one of, at once."""
    pairs = {(i, n) for out in C.CRAFTED for i, n in ingredient_counts(out).items() if n > 1}
    return tuple(sorted(pairs))


def recipe_counts(item: str) -> dict[str, int]:
    """Units of every item that one ``item`` consumes down its recipe tree (a treasure's tool
    counts once), the item itself excluded: ``recipe_counts("ladder")`` has wood 2."""
    counts: dict[str, int] = {}
    for i in C.ingredients(item):
        counts[i] = counts.get(i, 0) + 1
        for k, n in recipe_counts(i).items():
            counts[k] = counts.get(k, 0) + n
    return counts


SIDE_COSTS = ("held", "surplus", "leftover")


def _side_cost_fn(item: str, kind: str, count: int = 1) -> Callable:
    # the task's reward takes 0.1 per unit of any item held but the goal: a give_X run that
    # ends holding more than its teleport would have (X) is charged the same way. "held"
    # charges every other unit, the ingredients X's recipe uses too (their charge comes at
    # once, the credit when crafting consumes them later); "surplus" charges only the units
    # beyond what X's recipe tree consumes, so gathering ingredients is free, but so is a
    # spare ingredient still held at the end; "leftover" charges as "surplus" until X is
    # held (``count`` of it) and as "held" from then on: gathering is free, what the run
    # leaves over is not.
    item_id = C.KIND_ID[item]
    free = np.zeros(C.NUM_KINDS, np.float32)
    if kind != "held":
        for k, n in recipe_counts(item).items():
            free[C.KIND_ID[k]] = n
    others = np.ones(C.NUM_KINDS, np.float32)
    others[item_id] = 0.0
    satisfied = _held_fn(item_id, count, True)  # the template's own satisfied

    def fn(state: CraftState, params: CraftParams) -> jax.Array:
        allowed = free
        if kind == "leftover":
            allowed = jnp.where(satisfied(state, params), 0.0, free)
        extra = jnp.maximum(state.inventory.astype(jnp.float32) - allowed, 0.0)
        return 0.1 * jnp.sum(extra * others)
    return fn


def make_templates(side_cost: str = "held") -> dict[str, OptionTemplate]:
    """``give_<item>`` for the 6 primitives and 18 crafted items; ``side_cost`` picks what
    their side cost charges (``SIDE_COSTS``, see ``_side_cost_fn``)."""
    if side_cost not in SIDE_COSTS:
        raise ValueError(f"side_cost must be one of {SIDE_COSTS}, got {side_cost!r}")
    out = {}
    for item, count in [(item, 1) for item in C.ITEMS] + list(counted_ingredients()):
        item_id = C.KIND_ID[item]
        name = C.give_name(item, count)
        how = f"at workshop{C.WORKSHOPS.index(C.WORKSHOP_OF[item])}" if item in C.CRAFTED else ""
        what = f"obtain one {item}" if count == 1 else f"hold {count} {item}"
        out[name] = OptionTemplate(
            name=name,
            satisfied=_held_fn(item_id, count, True),
            initiation=_held_fn(item_id, count, False),
            k_max=count * C.STEP_CAP[item],
            teleport=teleport_of(item, count),
            nominal_steps=count * C.NOMINAL_STEPS[item],
            description=f"{what} {how}".strip(),
            side_cost=_side_cost_fn(item, side_cost, count),
        )
    return out


def recipe_children(task: str) -> dict[str, list[str]]:
    """task -> the give template of each direct ingredient, for the count one USE needs
    (``give_wood_x2`` where two are), + primitives, recursively (a treasure's tool counts).
    ``give_X_xN`` may call ``give_X`` for the first unit besides X's own ingredients."""
    goal = C.TASKS[task]
    children: dict[str, list[str]] = {}

    def add(option: str, item: str, count: int = 1) -> None:
        needed = ingredient_counts(item)
        kids = [C.give_name(i, n) for i, n in needed.items()]
        children[option] = ([C.give_name(item)] if count > 1 else []) + kids + ["primitives"]
        for i, n in needed.items():
            if C.give_name(i, n) not in children:
                add(C.give_name(i, n), i, n)
        if count > 1 and C.give_name(item) not in children:
            add(C.give_name(item), item)

    add(task, goal)
    return children


PAPER_CHILDREN = {
    "get_gem": {
        "get_gem": ["give_axe", "primitives"],
        "give_axe": ["give_stick", "give_iron", "primitives"],
        "give_stick": ["give_wood", "primitives"],
        "give_iron": ["primitives"],
        "give_wood": ["primitives"],
    },
    "get_gold": {
        "get_gold": ["give_bridge", "primitives"],
        "give_bridge": ["give_wood", "give_iron", "primitives"],
        "give_wood": ["primitives"],
        "give_iron": ["primitives"],
    },
}


def hierarchy_names(task: str) -> tuple[str, ...]:
    """Hierarchy names offered for a task, the default first."""
    C.check_task(task)
    return (("paper",) if task in PAPER_CHILDREN else ()) + ("recipe", "flat")


def default_hierarchy_name(task: str) -> str:
    """"paper" where the paper defines one (get_gem, get_gold), else "recipe"."""
    return hierarchy_names(task)[0]


def make_hierarchies(env, task: str) -> dict[str, Hierarchy]:
    """name -> Hierarchy for ``task``, in ``hierarchy_names`` order (default first)."""
    out, best = {}, best_return(task)
    for name in hierarchy_names(task):
        if name == "paper":
            children = PAPER_CHILDREN[task]
        elif name == "recipe":
            children = recipe_children(task)
        else:  # flat: the task over the primitive actions
            out[name] = next(iter(out.values())).flattened()
            continue
        out[name] = declare(env, task, children, success_ceiling=best)
    return out
