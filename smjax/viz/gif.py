"""Write frames (RGB uint8 arrays) as an animated GIF with Pillow."""
from __future__ import annotations

import os
from typing import Callable, Sequence

import numpy as np
from PIL import Image


def write_gif(frames: Sequence[np.ndarray], path: str | os.PathLike, fps: float = 8) -> str:
    """Write ``frames`` (each H x W x 3 uint8, all the same shape) to ``path``; returns the path."""
    frames = [np.asarray(f) for f in frames]
    if not frames:
        raise ValueError("write_gif needs at least one frame, got none")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps!r}")
    shape = frames[0].shape
    for i, frame in enumerate(frames):
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(
                f"frame {i} must be an (H, W, 3) uint8 array, got {frame.shape} {frame.dtype}"
            )
        if frame.shape != shape:
            raise ValueError(f"frame {i} has shape {frame.shape}, frame 0 has {shape}")
    images = [Image.fromarray(f) for f in frames]
    images[0].save(
        path, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0,
    )
    return str(path)


def rollout_frames(render: Callable, states: Sequence) -> list[np.ndarray]:
    """Render each of a list of (unbatched) states with ``render(state) -> image``."""
    return [np.asarray(render(s), np.uint8) for s in states]
