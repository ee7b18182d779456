"""Visualisation helpers: frame rendering and GIF writing."""
from smjax.viz.gif import rollout_frames, write_gif

__all__ = ["write_gif", "rollout_frames"]
