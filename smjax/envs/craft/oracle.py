"""A scripted oracle for Craft: reads the recipe tree, walks shortest paths, USEs.

``oracle_action(state, params, goal_item)`` is a pure, stateless function of one
(unbatched) state: jit- and vmap-able. It decides in two stages.

1. **What next** (``target_code``): a kind id to go and USE, by the recipe plan's rule
   (``recipe_plan.next_target``) on the inventory and on which treasures lie open.
2. **How to get there** (``cost_to_go``): a cost-to-go field over the 12 x 12 grid by
   iterated min-plus relaxation (Bellman-Ford with a 4-neighbour stencil, run until it
   stops changing), from the *stand cells* (cells 4-adjacent to a target cell). Empty cells
   cost 1; a primitive in the way can be grabbed and walked through at a cost of
   ``CLEAR_COST`` (so it happens only when no open path is shorter by that much: every
   held item costs 0.1 reward); stone costs 2 while an axe is held (mined, axe kept); water
   costs ``BRIDGE_COST`` while a bridge is held (bridged, bridge used up: a treasure whose
   own water cells can only be reached across other water takes two bridges); all else
   (boundary, workshops, targets) blocks. The agent then: USEs if it faces a
   target; turns toward an adjacent target (a move into an occupied cell only turns);
   otherwise steps to the neighbour of least cost-to-go, turning to it and USEing first
   where that neighbour must be cleared.

``oracle_decide`` also reports whether the oracle is stuck (its target is unreachable
even through clearable cells, or absent from the map); stuck, it returns DOWN.

The plan's results (``ORDERS``, ``COUNTS``, ``ingredient_counts``, ``solvable_items``,
``best_return``) are importable from here too.
"""
from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from smjax.envs.craft import constants as C
from smjax.envs.craft.recipe_plan import (
    COUNTS, ORDERS, next_target,
    best_return as best_return, ingredient_counts as ingredient_counts,
    solvable_items as solvable_items,
)
from smjax.envs.craft.types import CraftParams, CraftState

N = C.GRID_SIZE
INF = 1 << 20
CLEAR_COST = 50  # cost-to-go of grabbing a primitive that is in the way (and walking on)
MINE_COST = 2  # of mining a stone in the way while an axe is held (USE, then step)
# of bridging a water cell in the way while a bridge is held: it uses the bridge up, so
# another must be made before the treasure's own water can go (a second trip)
BRIDGE_COST = 200
PRIM_LO, PRIM_HI = C.PRIMITIVE_IDS[0], C.PRIMITIVE_IDS[-1]


# --------------------------------------------------------------------------------------
# What next, how to get there, the action


def _shift(a: jax.Array, dx: int, dy: int, fill) -> jax.Array:
    """out[x, y] = a[x + dx, y + dy] (``fill`` outside the grid)."""
    pad = jnp.pad(a, 1, constant_values=fill)
    return jax.lax.slice(pad, (1 + dx, 1 + dy), (1 + dx + N, 1 + dy + N))


def _any_neighbour(mask: jax.Array) -> jax.Array:
    out = jnp.zeros_like(mask)
    for dx, dy in C.DIRECTION_DELTAS:
        out = out | _shift(mask, int(dx), int(dy), False)
    return out


def _item_id(item) -> int:
    if isinstance(item, str):
        name = C.TASKS.get(item, item)
        if name not in C.KIND_ID or C.KIND_ID[name] < PRIM_LO:
            raise ValueError(f"unknown craft item or task {item!r}; items: {', '.join(C.ITEMS)}")
        return C.KIND_ID[name]
    return int(item)


def target_code(state: CraftState, item) -> jax.Array:
    """int32 kind to USE next toward one more ``item`` (static name or kind id)."""
    grid = state.grid
    inv = state.inventory
    open_cell = (grid == C.EMPTY) | ((grid >= PRIM_LO) & (grid <= PRIM_HI))

    def exposed(treasure: int) -> jax.Array:
        return jnp.any((grid == treasure) & _any_neighbour(open_cell))

    code = next_target(_item_id(item), inv, exposed, jnp.where, ORDERS, COUNTS)
    return jnp.asarray(code, jnp.int32)


def target_mask(grid: jax.Array, code: jax.Array) -> jax.Array:
    """bool [12, 12]: the cells to USE for target ``code`` (see ``target_code``)."""
    is_barrier = (code == C.WATER) | (code == C.STONE)
    treasure = jnp.where(code == C.WATER, C.GOLD, C.GEM)
    near_treasure = _any_neighbour(grid == treasure)
    return (grid == code) & (~is_barrier | near_treasure)


def cost_to_go(state: CraftState, mask: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(V, cost), int32 [12, 12]: steps-to-target field and the per-cell entry cost."""
    grid = state.grid
    is_prim = (grid >= PRIM_LO) & (grid <= PRIM_HI)
    mine = (grid == C.STONE) & (state.inventory[C.AXE] > 0)
    cross = (grid == C.WATER) & (state.inventory[C.BRIDGE] > 0)
    cost = jnp.where(grid == C.EMPTY, 1,
                     jnp.where(is_prim, CLEAR_COST, jnp.where(
                         mine, MINE_COST, jnp.where(cross, BRIDGE_COST, INF))))
    cost = jnp.where(mask, INF, cost).astype(jnp.int32)
    passable = cost < INF
    v0 = jnp.where(passable & _any_neighbour(mask), 0, INF).astype(jnp.int32)
    through = jnp.minimum(cost, INF)  # cost of entering each cell

    def relax(v):
        step = jnp.minimum(v + through, INF)
        best = v
        for dx, dy in C.DIRECTION_DELTAS:
            best = jnp.minimum(best, _shift(step, int(dx), int(dy), INF))
        return jnp.where(passable, best, INF)

    def cond(c):
        v, prev, i = c
        return jnp.any(v != prev) & (i < N * N)

    def body(c):
        v, _, i = c
        return relax(v), v, i + 1

    v, _, _ = jax.lax.while_loop(cond, body, (relax(v0), v0, jnp.int32(1)))
    return v, cost


def oracle_decide(state: CraftState, item) -> tuple[jax.Array, dict]:
    """(action int32 in 0..4, info) toward one more ``item`` from ``state``.

    info: ``target`` (the kind id aimed at), ``stuck`` (no way to any target cell),
    ``distance`` (cost-to-go from the agent's cell; ``INF`` when stuck).
    """
    return _decide(state, target_code(state, item), _item_id(item))


def _decide(state: CraftState, code: jax.Array, item_id) -> tuple[jax.Array, dict]:
    grid = state.grid
    mask = target_mask(grid, code)
    v, cost = cost_to_go(state, mask)
    x, y = state.pos[0], state.pos[1]
    deltas = jnp.asarray(C.DIRECTION_DELTAS)
    nx = jnp.clip(x + deltas[:, 0], 0, N - 1)
    ny = jnp.clip(y + deltas[:, 1], 0, N - 1)
    n_target = mask[nx, ny]  # [4]
    n_score = jnp.minimum(cost[nx, ny] + v[nx, ny], INF)
    n_kind = grid[nx, ny]
    faces_target = n_target[state.direction]
    turn_to = jnp.argmax(n_target).astype(jnp.int32)
    best = jnp.argmin(n_score).astype(jnp.int32)
    stuck = ~jnp.any(n_target) & (n_score[best] >= INF)
    must_clear = n_kind[best] != C.EMPTY
    walk = jnp.where(must_clear & (state.direction == best), C.USE, best)
    action = jnp.where(faces_target, C.USE,
                       jnp.where(jnp.any(n_target), turn_to, jnp.where(stuck, C.DOWN, walk)))
    done = state.inventory[item_id] > 0
    action = jnp.where(done, C.DOWN, action).astype(jnp.int32)
    here = jnp.where(jnp.any(n_target), 0, n_score[best])
    return action, {"target": code, "stuck": stuck & ~done, "distance": here}


def oracle_action(state: CraftState, params: CraftParams | None = None, goal_item=None):
    """The oracle's primitive action (int32 in 0..4) toward ``goal_item``.

    ``goal_item``: an item or task name (``"gem"``, ``"get_gem"``) or kind id, static; None
    takes the task's goal from ``params.goal`` (traced: the target is then selected among
    all 24 items, so prefer naming it).
    """
    if goal_item is not None:
        return oracle_decide(state, goal_item)[0]
    if params is None:
        raise ValueError("oracle_action needs goal_item or params (whose goal it reads)")
    return oracle_decide_traced(state, params.goal)[0]


def oracle_decide_traced(state: CraftState, item_id: jax.Array, count: jax.Array | int = 1):
    """``oracle_decide`` for a traced item kind id (one field, target selected by id),
    done once ``count`` of it are held."""
    codes = jnp.stack([target_code(state, C.KIND_ID[name]) for name in C.ITEMS])
    ids = jnp.asarray([C.KIND_ID[name] for name in C.ITEMS], jnp.int32)
    code = codes[jnp.argmax(ids == item_id)]
    grid_done = state.inventory[item_id] >= count
    action, info = _decide(state, code, 0)  # item 0 (empty) is never held: no 'done' here
    action = jnp.where(grid_done, C.DOWN, action).astype(jnp.int32)
    info = dict(info, stuck=info["stuck"] & ~grid_done)
    return action, info


# --------------------------------------------------------------------------------------
# Controller form: give_<item> templates played by the oracle


def _give_fn(key: jax.Array, state: CraftState, params: CraftParams, data: dict) -> jax.Array:
    return oracle_decide_traced(state, data["item_id"], data["count"])[0]


def give_controller(item: str, count: int = 1) -> Callable:
    """A ``Parametric`` controller (key, state, params) -> action obtaining ``item`` until
    ``count`` are held, usable as ``OptionTemplate.controller`` (one family for every
    give_X)."""
    from smjax.options import Parametric

    return Parametric(_give_fn, {"item_id": np.int32(_item_id(item)), "count": np.int32(count)})


def oracle_templates(env) -> dict:
    """``env.templates()`` with every give_X realised by the oracle (no teleport)."""
    import dataclasses

    return {name: dataclasses.replace(tpl, teleport=None,
                                      controller=give_controller(*C.give_target(name)))
            for name, tpl in env.templates().items()}


def oracle_hierarchy(env, task: str | None = None, name: str | None = None):
    """The env's hierarchy ``name`` (default: the task's default) with oracle leaves.

    Its templates are played by ``give_controller``; learned options above them still
    choose which template to call.
    """
    from smjax.options import Hierarchy

    task = env.config.task if task is None else task
    base = env.hierarchies()
    h = base[next(iter(base)) if name is None else name]
    return Hierarchy(task=task, children=dict(h.children), templates=oracle_templates(env),
                     primitive_names=tuple(env.primitive_action_names))
