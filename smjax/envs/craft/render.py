"""Draw one Craft state as an RGB uint8 image (host-side, with Pillow).

Layout: the 12 x 12 map (y up, so the top image row is y = 11), 16 px per cell, each kind a
distinct colour with its ASCII glyph printed on it; the agent is a white disc with a red
wedge pointing where it faces; below the map an inventory strip: one coloured square per
held item with its count and a three-letter name.
"""
from __future__ import annotations

import functools

import numpy as np

from smjax.envs.craft import constants as C

N = C.GRID_SIZE
CELL = 16
STRIP_ROW = 20  # height of one inventory strip row
ITEMS_PER_ROW = 4

_BASE_COLOURS = {
    "empty": (236, 230, 210), "boundary": (60, 60, 60), "workshop0": (150, 90, 40),
    "workshop1": (120, 60, 140), "workshop2": (70, 110, 150), "water": (60, 130, 230),
    "stone": (130, 130, 125), "iron": (170, 180, 195), "grass": (90, 190, 70),
    "wood": (120, 80, 30), "rock": (95, 90, 80), "gold": (240, 200, 30), "gem": (40, 220, 210),
}


def _colour(kind: int) -> tuple[int, int, int]:
    name = C.KIND_NAMES[kind]
    if name in _BASE_COLOURS:
        return _BASE_COLOURS[name]
    # Crafted items (never on the map): spread hues deterministically.
    rng = np.random.default_rng(kind)
    return tuple(int(v) for v in rng.integers(60, 230, 3))


COLOURS = np.array([_colour(k) for k in range(C.NUM_KINDS)], np.uint8)


@functools.cache
def _font():
    from PIL import ImageFont

    return ImageFont.load_default()


def render_state(grid, pos, direction, inventory) -> np.ndarray:
    """RGB uint8 (H, W, 3) for one state given as arrays (jax or numpy)."""
    # Pillow only where a picture is drawn: a training run never imports it
    from PIL import Image, ImageDraw

    grid = np.asarray(grid)
    inventory = np.asarray(inventory)
    if grid.shape != (N, N):
        raise ValueError(f"render needs one unbatched state (grid {N}x{N}), got {grid.shape}")
    x, y = (int(v) for v in np.asarray(pos))
    direction = int(np.asarray(direction))
    held = [k for k in range(C.NUM_KINDS) if inventory[k] > 0]
    strip_rows = max(1, -(-len(held) // ITEMS_PER_ROW))
    width, height = N * CELL, N * CELL + strip_rows * STRIP_ROW
    # Map: colour every cell by kind (image row 0 is y = 11).
    image = np.zeros((height, width, 3), np.uint8)
    cells = COLOURS[grid.T[::-1]]  # [row, col, 3]
    image[: N * CELL] = np.repeat(np.repeat(cells, CELL, 0), CELL, 1)
    image[N * CELL:] = 250
    pil = Image.fromarray(image)
    draw = ImageDraw.Draw(pil)
    for gx in range(N):
        for gy in range(N):
            kind = int(grid[gx, gy])
            if kind in (C.EMPTY, C.BOUNDARY):
                continue
            left, top = gx * CELL, (N - 1 - gy) * CELL
            draw.text((left + 4, top + 2), C.GLYPH_OF_KIND.get(kind, "?"), fill=(0, 0, 0),
                      font=_font())
    # Agent: disc plus a wedge towards the facing direction.
    left, top = x * CELL, (N - 1 - y) * CELL
    cx, cy = left + CELL / 2, top + CELL / 2
    draw.ellipse([left + 2, top + 2, left + CELL - 3, top + CELL - 3], fill=(255, 255, 255),
                 outline=(0, 0, 0))
    dx, dy = C.DIRECTION_DELTAS[direction]
    tip = (cx + dx * (CELL / 2 - 1), cy - dy * (CELL / 2 - 1))  # image y grows downward
    side = (-dy * 4, -dx * 4)
    draw.polygon([tip, (cx + side[0], cy + side[1]), (cx - side[0], cy - side[1])],
                 fill=(220, 30, 30))
    # Inventory strip.
    for n, kind in enumerate(held):
        col, row = n % ITEMS_PER_ROW, n // ITEMS_PER_ROW
        left = col * (width // ITEMS_PER_ROW) + 2
        top = N * CELL + row * STRIP_ROW + 3
        draw.rectangle([left, top, left + 13, top + 13], fill=tuple(int(c) for c in COLOURS[kind]),
                       outline=(0, 0, 0))
        label = f"{int(inventory[kind])}{C.KIND_NAMES[kind][:3]}"
        draw.text((left + 16, top + 1), label, fill=(0, 0, 0), font=_font())
    return np.asarray(pil, np.uint8)
