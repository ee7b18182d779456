"""Where an observation holds grids: the data an environment declares so that a learner
may read a spatial window with a convolution instead of a flat dense layer.

An environment lists its grids (``Environment.observation_layout``): each is a block of the
*flattened* observation, ``height * width * channels`` values from ``start`` in C order
(row, then column, then channel). The learners know nothing of the environment: a
convolutional torso (``--agent torso=conv``) reshapes each declared block and reads the
rest of the observation as flat features. Nothing else in smjax reads the layout.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence


class Grid(NamedTuple):
    """A ``height x width x channels`` block of the flat observation from ``start``."""

    start: int
    height: int
    width: int
    channels: int

    @property
    def size(self) -> int:
        return self.height * self.width * self.channels

    @property
    def stop(self) -> int:
        return self.start + self.size


def check_layout(grids: Sequence[Grid], obs_size: int) -> tuple[Grid, ...]:
    """The grids as a tuple, or ValueError naming the first that is malformed, out of the
    observation's ``obs_size`` values, or overlapping another."""
    grids = tuple(Grid(*g) for g in grids)
    for g in grids:
        if min(g.height, g.width, g.channels) < 1 or g.start < 0:
            raise ValueError(f"observation grid {g} needs start >= 0 and every size >= 1")
        if g.stop > obs_size:
            raise ValueError(f"observation grid {g} ends at {g.stop}, past the observation's "
                             f"{obs_size} values")
    ordered = sorted(grids)
    for a, b in zip(ordered, ordered[1:]):
        if b.start < a.stop:
            raise ValueError(f"observation grids {a} and {b} overlap")
    return grids


def flat_rest(grids: Sequence[Grid], obs_size: int) -> list[int]:
    """Indices of the observation's values that no grid covers, in order."""
    covered = set()
    for g in grids:
        covered.update(range(g.start, g.stop))
    return [i for i in range(obs_size) if i not in covered]
