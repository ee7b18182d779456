"""Craft's kinds, recipes, tasks, step caps and template durations (plain data, no JAX).

Kind ids (one id space for grid cells and inventory slots, 31 ids as in the reference,
whose index reserves slot 0 for "invalid"):

====  ===========  =====  ====================================================
id    name         glyph  role
====  ===========  =====  ====================================================
0     empty        ``.``  an empty cell; the reference's "invalid" slot, never hot
1     boundary     ``#``  the outer ring
2-4   workshop0-2  ``0``  workbench, toolshed, factory (``1``, ``2``)
5     water        ``~``  removed by USE with a bridge (which is consumed)
6     stone        ``S``  removed by USE with an axe (which is kept)
7-12  iron, grass, wood, rock, gold, gem (primitives: grabbable, glyphs i g w r G E)
13-30 the 18 crafted items in recipe order (plank .. goldarrow), never on the grid
====  ===========  =====  ====================================================

Grids are indexed ``grid[x, y]`` (x to the right, y up, y = 0 the bottom row).
"""
from __future__ import annotations

import numpy as np

GRID_SIZE = 12
NUM_KINDS = 31

EMPTY, BOUNDARY = 0, 1
WORKSHOPS = (2, 3, 4)
WATER, STONE = 5, 6
PRIMITIVES = ("iron", "grass", "wood", "rock", "gold", "gem")
# Recipes in the reference file's order: (output, inputs, workshop index). All yield 1 and
# need one of each input.
RECIPES: tuple[tuple[str, tuple[str, ...], int], ...] = (
    ("plank", ("wood",), 0),
    ("stick", ("wood",), 1),
    ("cloth", ("grass",), 2),
    ("rope", ("grass",), 0),
    ("bridge", ("wood", "iron"), 2),
    ("bundle", ("wood", "grass"), 1),
    ("hammer", ("wood", "rock"), 0),
    ("knife", ("iron", "rock"), 2),
    ("bed", ("plank", "grass"), 1),
    ("axe", ("stick", "iron"), 0),
    ("shears", ("stick", "iron"), 1),
    ("ladder", ("plank", "stick"), 2),
    ("slingshot", ("rope", "wood", "rock"), 1),
    ("arrow", ("knife", "wood"), 0),
    ("bow", ("rope", "bundle"), 2),
    ("bench", ("hammer", "wood", "iron"), 2),
    ("flag", ("stick", "cloth", "iron"), 0),
    ("goldarrow", ("gold", "wood"), 0),
)
CRAFTED = tuple(r[0] for r in RECIPES)
ITEMS = PRIMITIVES + CRAFTED  # everything that can be held

KIND_NAMES: tuple[str, ...] = (
    ("empty", "boundary", "workshop0", "workshop1", "workshop2", "water", "stone")
    + PRIMITIVES + CRAFTED
)
assert len(KIND_NAMES) == NUM_KINDS
KIND_ID = {name: i for i, name in enumerate(KIND_NAMES)}
PRIMITIVE_IDS = tuple(KIND_ID[p] for p in PRIMITIVES)
GOLD, GEM = KIND_ID["gold"], KIND_ID["gem"]
AXE, BRIDGE = KIND_ID["axe"], KIND_ID["bridge"]
RECIPE_IDS: tuple[tuple[int, tuple[int, ...], int], ...] = tuple(
    (KIND_ID[out], tuple(KIND_ID[i] for i in ins), WORKSHOPS[w]) for out, ins, w in RECIPES
)
WORKSHOP_OF = {out: WORKSHOPS[w] for out, _, w in RECIPES}  # item name -> workshop kind id

# Glyphs of the ASCII format (docs/environments.md, Craft); '@' marks the agent (on an empty cell).
GLYPH_OF_KIND = {
    EMPTY: ".", BOUNDARY: "#", 2: "0", 3: "1", 4: "2", WATER: "~", STONE: "S",
    KIND_ID["iron"]: "i", KIND_ID["grass"]: "g", KIND_ID["wood"]: "w", KIND_ID["rock"]: "r",
    GOLD: "G", GEM: "E",
}
KIND_OF_GLYPH = {g: k for k, g in GLYPH_OF_KIND.items()}
AGENT_GLYPH = "@"

# Actions. NOOP (5) is accepted by step_env but is not in the action space: it lets an
# impossible teleport be a do-nothing step.
DOWN, UP, LEFT, RIGHT, USE, NOOP = 0, 1, 2, 3, 4, 5
NUM_ACTIONS = 5
ACTION_NAMES = ("down", "up", "left", "right", "use")
# (dx, dy) per facing direction, indexed by DOWN/UP/LEFT/RIGHT.
DIRECTION_DELTAS = np.array([[0, -1], [0, 1], [-1, 0], [1, 0]], np.int32)

# The tool a treasure needs (gold sits on an island of water, gem in a cave of stone). The
# recipe hierarchies and the size rule below treat it as the treasure's "ingredient".
TREASURE_TOOL = {"gold": "bridge", "gem": "axe"}


def ingredients(item: str) -> tuple[str, ...]:
    """Direct ingredients of an item: recipe inputs, a treasure's tool, or () for the rest."""
    for out, ins, _ in RECIPES:
        if out == item:
            return ins
    return (TREASURE_TOOL[item],) if item in TREASURE_TOOL else ()


def tree_size(item: str) -> int:
    """Nodes of the item's recipe tree, counting multiplicity (the item itself included)."""
    return 1 + sum(tree_size(i) for i in ingredients(item))


def needs(item: str) -> set[str]:
    """Every item in the recipe tree below ``item``."""
    out: set[str] = set()
    for i in ingredients(item):
        out |= {i} | needs(i)
    return out


# Step caps. The reference's caps (wood/iron 100, stick 200, bridge 300, axe/gold 400,
# gem 500) are all exactly 100 x tree_size; the other tasks use the same rule.
STEP_CAP = {item: 100 * tree_size(item) for item in ITEMS}

# Nominal durations d of a teleported template (the caller's SMDP discount is gamma^d).
# Reference values where it has them; otherwise by recipe-tree size: 1 -> 25, 2 -> 40,
# 3-4 -> 50, >= 5 -> 75, and 100 for anything that needs a treasure.
_REFERENCE_NOMINAL = {"wood": 25, "iron": 25, "stick": 40, "axe": 50, "bridge": 50,
                      "gold": 100, "gem": 100}


def _nominal(item: str) -> int:
    if item in _REFERENCE_NOMINAL:
        return _REFERENCE_NOMINAL[item]
    if needs(item) & {"gold", "gem"}:
        return 100
    size = tree_size(item)
    return 25 if size == 1 else 40 if size == 2 else 50 if size <= 4 else 75


NOMINAL_STEPS = {item: _nominal(item) for item in ITEMS}

# Tasks: get_<primitive>, make_<crafted>; task name -> goal item.
TASKS: dict[str, str] = {f"get_{p}": p for p in PRIMITIVES}
TASKS.update({f"make_{c}": c for c in CRAFTED})


def world_kind(task: str) -> str:
    """'island' for tasks that need gold, 'cave' for tasks needing a gem, else 'plain'."""
    goal = TASKS[task]
    tree = needs(goal) | {goal}
    if "gold" in tree:
        return "island"
    if "gem" in tree:
        return "cave"
    return "plain"


def give_name(item: str, count: int = 1) -> str:
    """The template promising ``count`` of ``item``: ``give_wood``, ``give_wood_x2``."""
    return f"give_{item}" if count == 1 else f"give_{item}_x{count}"


def give_target(name: str) -> tuple[str, int]:
    """(item, count) a ``give_`` template name promises: inverse of ``give_name``."""
    item, _, count = name[len("give_"):].partition("_x")
    if not name.startswith("give_") or item not in ITEMS or (count and not count.isdigit()):
        raise ValueError(f"not a craft give template name: {name!r}")
    return item, int(count or 1)


def check_task(task: str) -> str:
    if not isinstance(task, str) or task not in TASKS:
        raise ValueError(f"unknown craft task {task!r}; valid tasks: {', '.join(TASKS)}")
    return task
