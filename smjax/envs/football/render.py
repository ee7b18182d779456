"""Draw one (unbatched) state: pitch, goals, both teams with shirt numbers, ball, score.

Host-side (numpy + Pillow), not jitted: rendering is for inspection and GIFs.
"""
from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from smjax.envs.football import constants as C
from smjax.envs.football.types import FootballState

WIDTH, HEIGHT, MARGIN = 480, 232, 20
LEFT_COLOUR, RIGHT_COLOUR = (230, 60, 50), (60, 110, 240)


def _to_px(x, y):
    sx = (WIDTH - 2 * MARGIN) / (2 * C.FIELD_X)
    sy = (HEIGHT - 2 * MARGIN - 12) / (2 * C.FIELD_Y)
    return MARGIN + (x + C.FIELD_X) * sx, MARGIN + 12 + (y + C.FIELD_Y) * sy


def render_frame(state: FootballState) -> np.ndarray:
    """RGB uint8 (HEIGHT, WIDTH, 3); y grows downward on screen, as in GRF."""
    if np.ndim(state.ball_pos) != 1:
        raise ValueError("render takes one unbatched state; index a batch first, e.g. "
                         "jax.tree.map(lambda x: x[0], state)")
    img = Image.new("RGB", (WIDTH, HEIGHT), (40, 130, 50))
    draw = ImageDraw.Draw(img)
    line = (235, 235, 235)
    draw.rectangle([_to_px(-1, -C.FIELD_Y), _to_px(1, C.FIELD_Y)], outline=line)
    draw.line([_to_px(0, -C.FIELD_Y), _to_px(0, C.FIELD_Y)], fill=line)
    cx, cy = _to_px(0, 0)
    r = C.CENTRE_CIRCLE * (WIDTH - 2 * MARGIN) / 2
    draw.ellipse([cx - r, cy - r * 0.85, cx + r, cy + r * 0.85], outline=line)
    for s in (-1.0, 1.0):
        box = [_to_px(s * 1.0, -C.PENALTY_BOX_Y), _to_px(s * C.PENALTY_BOX_X, C.PENALTY_BOX_Y)]
        draw.rectangle([min(box[0][0], box[1][0]), box[0][1], max(box[0][0], box[1][0]), box[1][1]],
                       outline=line)
        g0, g1 = _to_px(s * 1.0, -C.GOAL_HALF_WIDTH), _to_px(s * 1.03, C.GOAL_HALF_WIDTH)
        draw.rectangle([min(g0[0], g1[0]), g0[1], max(g0[0], g1[0]), g1[1]], fill=(250, 250, 250))
    pos = np.asarray(state.pos)
    for i in range(C.NUM_TOTAL):
        px, py = _to_px(*pos[i])
        colour = LEFT_COLOUR if i < C.NUM_PLAYERS else RIGHT_COLOUR
        if i % C.NUM_PLAYERS == C.GOALKEEPER:
            colour = tuple(min(255, c + 80) for c in colour)
        draw.ellipse([px - 5, py - 5, px + 5, py + 5], fill=colour, outline=(0, 0, 0))
        draw.text((px - 3, py - 16), str(i % C.NUM_PLAYERS), fill=(255, 255, 255))
    bx, by, bz = np.asarray(state.ball_pos)
    bpx, bpy = _to_px(bx, by)
    rb = 3 + 20 * float(bz)          # the ball looks bigger the higher it flies
    draw.ellipse([bpx - rb, bpy - rb, bpx + rb, bpy + rb], fill=(255, 255, 255), outline=(0, 0, 0))
    score = np.asarray(state.score)
    mode = C.GAME_MODE_NAMES[int(state.game_mode)]
    draw.text((MARGIN, 4), f"LEFT {int(score[0])} - {int(score[1])} RIGHT   step {int(state.step)}   {mode}",
              fill=(255, 255, 255))
    return np.asarray(img, dtype=np.uint8)
