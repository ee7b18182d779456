"""Craft's recipe plan: per crafted item, which ingredients to obtain, in which order and
how many, worked out on the inventory alone (numpy) once at import.

``next_target`` is the decision rule the plan and the oracle (``oracle.target_code``)
share: the kind to USE next toward one more item, read off the recipe tree and the
inventory. For a primitive: that primitive. For a crafted item: the first of its direct
ingredients (in the planned order) held in fewer than the planned count is obtained first
(recursively), and once all are held its workshop is the target. For a treasure (gold,
gem): the treasure itself once some 4-neighbour of it is open; else, with its tool held
(bridge, axe), a barrier cell (water, stone) 4-adjacent to the treasure; else the tool,
recursively.

``plan`` simulates that rule on the inventory alone: one USE at a workshop fires every
recipe of it whose inputs are held, in file order, so e.g. a stick made while iron is held
becomes shears, and a hammer needs two wood (the plank recipe fires first).
"""
from __future__ import annotations

import itertools

import numpy as np

from smjax.envs.craft import constants as C

TREASURE_OF_BARRIER = {C.WATER: C.GOLD, C.STONE: C.GEM}
BARRIER_OF_TREASURE = {C.GOLD: C.WATER, C.GEM: C.STONE}
TOOL_OF_TREASURE = {C.KIND_ID[t]: C.KIND_ID[tool] for t, tool in C.TREASURE_TOOL.items()}
_RECIPE_OF = {out: (ins, ws) for out, ins, ws in C.RECIPE_IDS}


def fire_recipes_np(inv: np.ndarray, workshop: int) -> np.ndarray:
    """``dynamics.fire_recipes`` on a numpy inventory (one USE at ``workshop``)."""
    inv = inv.copy()
    for out, ins, at in C.RECIPE_IDS:
        if at == workshop and all(inv[i] > 0 for i in ins):
            for i in ins:
                inv[i] -= 1
            inv[out] += 1
    return inv


def _units_needed(item: int) -> dict[int, int]:
    """How many of each direct ingredient to hold before USE at the workshop, so that the
    USE yields ``item`` (earlier recipes of the same workshop may eat an input first)."""
    ins, ws = _RECIPE_OF[item]
    req = {i: 1 for i in ins}
    for _ in range(8):
        inv = np.zeros(C.NUM_KINDS, np.int64)
        for i, n in req.items():
            inv[i] = n
        if fire_recipes_np(inv, ws)[item] > 0:
            return req
        # replay the workshop's recipes in order; top up what was gone when ours came
        for out, rins, at in C.RECIPE_IDS:
            if at != ws:
                continue
            if out == item:
                for i in ins:
                    if inv[i] == 0:
                        req[i] += 1
                break
            if all(inv[i] > 0 for i in rins):
                for i in rins:
                    inv[i] -= 1
                inv[out] += 1
    return req


def next_target(item: int, inv, exposed, where, orders, counts):
    """The next kind to USE toward one more ``item`` (the plan's numpy inventory or the
    oracle's traced one).

    ``exposed(treasure)`` says whether a treasure has an open 4-neighbour; ``where`` is a
    select (``jnp.where`` or a Python one); a barrier kind (water, stone) as the target means
    "the barrier cells 4-adjacent to its treasure".
    """
    if item in TOOL_OF_TREASURE:
        tool = TOOL_OF_TREASURE[item]
        via_tool = where(inv[tool] > 0, BARRIER_OF_TREASURE[item],
                         next_target(tool, inv, exposed, where, orders, counts))
        return where(exposed(item), item, via_tool)
    if item not in _RECIPE_OF:
        return item
    _, ws = _RECIPE_OF[item]
    code = ws
    for i in reversed(orders[item]):
        code = where(inv[i] >= counts[item][i], code,
                     next_target(i, inv, exposed, where, orders, counts))
    return code


def _py_where(c, a, b):
    return a if c else b


def _simulate(goal: int, orders, counts, max_uses: int = 60):
    """Run the decision rule on the inventory alone from nothing; (uses, inventory) or None.

    None: the goal was never held within ``max_uses`` USEs, or the plan grabbed more than
    the map's 4 of some resource."""
    inv = np.zeros(C.NUM_KINDS, np.int64)
    open_ = {C.GOLD: False, C.GEM: False}
    grabbed = np.zeros(C.NUM_KINDS, np.int64)
    for uses in range(max_uses):
        if inv[goal] > 0:
            return uses, inv
        code = int(next_target(goal, inv, lambda t: open_[t], _py_where, orders, counts))
        if code in C.WORKSHOPS:
            inv = fire_recipes_np(inv, code)
        elif code in TREASURE_OF_BARRIER:
            open_[TREASURE_OF_BARRIER[code]] = True
            if code == C.WATER:
                inv[C.BRIDGE] -= 1
        else:
            inv[code] += 1
            grabbed[code] += 1
            if code not in (C.GOLD, C.GEM) and grabbed[code] > 4:
                return None
    return None


def plan() -> tuple[dict[int, tuple[int, ...]], dict[int, dict[int, int]]]:
    """Per crafted item: the order to obtain its ingredients in, and how many of each.

    Items are planned leaves first; each tries every order of its direct ingredients and
    keeps the one whose simulated run succeeds in the fewest USEs, then with the fewest
    other items left over (each costs 0.1 reward). With none succeeding it keeps file order.
    """
    counts = {out: _units_needed(out) for out in _RECIPE_OF}
    orders: dict[int, tuple[int, ...]] = {}
    for out, ins, _ in C.RECIPE_IDS:  # inputs always come earlier in file order
        best, best_key = tuple(ins), None
        for perm in itertools.permutations(ins):
            trial = dict(orders)
            trial[out] = perm
            for o, i2, _ in C.RECIPE_IDS:  # later items: file order for now
                trial.setdefault(o, tuple(i2))
            res = _simulate(out, trial, counts)
            if res is None:
                continue
            uses, inv = res
            key = (uses, int(inv.sum() - inv[out]))
            if best_key is None or key < best_key:
                best, best_key = perm, key
        orders[out] = best
    return orders, counts


ORDERS, COUNTS = plan()


def _plan_outcome(name: str) -> tuple[int, int] | None:
    """(USEs, other items left held) of the plan for item ``name`` from nothing, or None."""
    goal = C.KIND_ID[name]
    res = _simulate(goal, ORDERS, COUNTS)
    return None if res is None else (res[0], int(res[1].sum() - res[1][goal]))


def ingredient_counts(item: str) -> dict[str, int]:
    """Units of each direct ingredient to hold at the workshop so that one USE yields
    ``item`` (in recipe order; a flag needs 2 sticks and 2 iron, as the axe recipe fires
    first and eats one of each); a treasure: its tool, 1; a primitive: none."""
    kind = C.KIND_ID[item]
    if kind in COUNTS:
        return {C.KIND_NAMES[i]: n for i, n in COUNTS[kind].items()}
    return {i: 1 for i in C.ingredients(item)}


def solvable_items() -> dict[str, tuple[int, int] | None]:
    """item -> (USEs, other items left held) of the plan from nothing, or None if it fails."""
    return {name: _plan_outcome(name) for name in C.ITEMS}


def best_return(task: str) -> float:
    """The best return (Craft's task success) of ``task``: 1 less 0.1 per item the plan
    leaves held beside the goal (make_bench: 0.8; multi-fire USE makes some leftovers
    unavoidable), or 1.0 where the plan fails (no lower bound known)."""
    res = _plan_outcome(C.TASKS[task])
    return 1.0 if res is None else round(max(0.0, 1.0 - 0.1 * res[1]), 6)

