"""Craft maps as text: ``from_ascii``, ``to_ascii``, ``inventory_dict`` and the reference map.

Legend (docs/environments.md, Craft): ``#`` boundary, ``.`` empty, ``0 1 2`` workshops, ``~`` water,
``S`` stone, ``i`` iron, ``g`` grass, ``w`` wood, ``r`` rock, ``G`` gold, ``E`` gem, ``@`` the
agent (standing on an empty cell, facing DOWN: the format has no facing glyphs, so
``to_ascii`` prints ``@`` whatever the facing). The first text row is the top row, y = 11.
Leading/trailing blank lines and the indentation common to all rows are ignored.
"""
from __future__ import annotations

import textwrap

import jax.numpy as jnp
import numpy as np

from smjax.envs.craft import constants as C
from smjax.envs.craft.types import CraftParams, CraftState, make_params

N = C.GRID_SIZE

# The reference's map for get_gold (agent at (8, 4) facing DOWN).
REFERENCE_GOLD_MAP = """\
############
#..........#
#r.....i...#
#..w...ggw.#
#.....g....#
#....2.i...#
#w.i1......#
#.i.....@wr#
#r.r...0...#
#....~~~...#
#....~G~..g#
############"""
# The same map for get_gem: water -> stone, gold -> gem.
REFERENCE_GEM_MAP = REFERENCE_GOLD_MAP.replace("~", "S").replace("G", "E")


def _rows(text: str) -> list[str]:
    if not isinstance(text, str):
        raise ValueError(f"ASCII map must be a string, got {type(text).__name__}")
    lines = textwrap.dedent(text).strip("\n").split("\n")
    return [line.rstrip() for line in lines]


def parse_ascii(text: str) -> tuple[np.ndarray, tuple[int, int]]:
    """(grid uint8 [12, 12] indexed [x, y], agent (x, y)); ValueError naming row and column."""
    rows = _rows(text)
    if len(rows) != N:
        raise ValueError(f"ASCII map must have {N} rows, got {len(rows)}")
    grid = np.zeros((N, N), np.uint8)
    agents = []
    for r, line in enumerate(rows):
        if len(line) != N:
            raise ValueError(f"ASCII map row {r} must have {N} columns, got {len(line)}: {line!r}")
        y = N - 1 - r
        for x, glyph in enumerate(line):
            if glyph == C.AGENT_GLYPH:
                agents.append((r, x))
                kind = C.EMPTY
            elif glyph in C.KIND_OF_GLYPH:
                kind = C.KIND_OF_GLYPH[glyph]
            else:
                raise ValueError(
                    f"unknown glyph {glyph!r} at row {r}, column {x}; valid glyphs: "
                    f"{''.join(C.KIND_OF_GLYPH)}{C.AGENT_GLYPH}"
                )
            on_ring = x in (0, N - 1) or y in (0, N - 1)
            if on_ring != (kind == C.BOUNDARY) or (on_ring and glyph == C.AGENT_GLYPH):
                what = "must be '#' (boundary ring)" if on_ring else "may not be '#' (interior)"
                raise ValueError(f"cell at row {r}, column {x} is {glyph!r} but {what}")
            grid[x, y] = kind
    if len(agents) != 1:
        where = ", ".join(f"row {r} column {c}" for r, c in agents)
        raise ValueError(f"ASCII map needs exactly one agent '@', found {len(agents)} ({where})")
    r, x = agents[0]
    return grid, (x, N - 1 - r)


def from_ascii(text: str, task: str = "get_gem", max_steps: int | None = None):
    """(state, params) for that fixed map; every reset with these params restores it.

    A ``get_X`` task on a map without any X, or a ``make_X`` task on a map without a raw
    material of X's recipe (make_stick without wood), can never succeed, so it is refused
    (ValueError): put it on the map (glyph in the module docstring) or pass the task the
    map is for. A map made to test rules rather than to be solved can carry an X in a
    corner nothing reaches."""
    grid, (x, y) = parse_ascii(text)
    goal = C.TASKS[C.check_task(task)]
    for kind in _kinds_needed(goal):
        if not (grid == C.KIND_ID[kind]).any():
            glyph = C.GLYPH_OF_KIND[C.KIND_ID[kind]]
            raise ValueError(f"the map holds no {kind} ({glyph!r}), which task {task!r} needs: it "
                             f"can never succeed on it; add a {kind} ({glyph!r}) to the map or "
                             f"pass the task the map is for (task=...)")
    state = CraftState(
        grid=jnp.asarray(grid),
        pos=jnp.array([x, y], jnp.int32),
        direction=jnp.int32(C.DOWN),
        inventory=jnp.zeros(C.NUM_KINDS, jnp.int32),
        step=jnp.int32(0),
    )
    params: CraftParams = make_params(task, max_steps=max_steps, fixed_state=state)
    return state, params


def _kinds_needed(goal: str) -> list[str]:
    """The raw materials ``goal`` cannot be had without: itself if it is one, else those of
    its recipe, all the way down. (Workshops and a treasure's tool are not required: a
    map made to show one rule may leave them out.)"""
    if goal in C.PRIMITIVES:
        return [goal]
    needed = []
    for item in C.ingredients(goal):
        needed += [kind for kind in _kinds_needed(item) if kind not in needed]
    return needed


def to_ascii(state: CraftState) -> str:
    """The map of one (unbatched) state as text (inverse of ``from_ascii`` up to facing)."""
    grid = np.asarray(state.grid)
    if grid.shape != (N, N):
        raise ValueError(f"to_ascii needs one unbatched state (grid {N}x{N}), got {grid.shape}")
    x, y = (int(v) for v in np.asarray(state.pos))
    lines = []
    for yy in range(N - 1, -1, -1):
        row = "".join(C.GLYPH_OF_KIND.get(int(grid[xx, yy]), "?") for xx in range(N))
        if yy == y:
            row = row[:x] + C.AGENT_GLYPH + row[x + 1:]
        lines.append(row)
    return "\n".join(lines)


def inventory_dict(state: CraftState) -> dict[str, int]:
    """{item name: count} of the items one (unbatched) state holds (count > 0 only)."""
    inv = np.asarray(state.inventory)
    if inv.shape != (C.NUM_KINDS,):
        raise ValueError(f"inventory_dict needs one unbatched state, got inventory {inv.shape}")
    return {C.KIND_NAMES[k]: int(inv[k]) for k in range(C.NUM_KINDS) if inv[k] > 0}
