"""The obstacles' broadphase: which obstacles can come within the detection distance of the
robot at all, without comparing the robot with every one (docs/design.md 18.3, "How many
obstacles").

Each obstacle's bounding capsule (:func:`~constraints.collision.geometry.bounding_segment`)
is held in its axis-aligned box ``[min(a, b) - r, max(a, b) + r]``; the boxes are sorted
by their lower x (a sweep and prune along x, Baraff 1992, in its one-query form). A query
box ``[low, high]`` (the robot's bounding capsules' boxes, together, grown by the
detection distance) meets only boxes whose lower x lies in ``[low_x - w, high_x]``, ``w``
the widest box along x: two binary searches find that window, and only its boxes are
compared on the three axes. A pair of capsules closer than ``d`` has boxes closer than
``d`` on every axis, so no obstacle that can be near is left out. A half-space has no box
(it is everywhere): it is always kept.

The cost of a query is the logarithm of the obstacles plus the obstacles in the window:
obstacles far from the robot along x cost nothing; :meth:`ObstacleBoxes.build` sorts
(``n log n``) when obstacles were added or moved.
"""

from __future__ import annotations

import numpy as np


class ObstacleBoxes:
    """The axis-aligned boxes of the obstacles' bounding capsules, sorted along x.

    starts, ends : (n, 3) each obstacle's bounding segment's ends (world).
    radii : (n,) each bounding capsule's radius; infinite for a half-space (always kept).
    """

    def __init__(self, starts: np.ndarray, ends: np.ndarray, radii: np.ndarray) -> None:
        self.count = len(radii)
        finite = np.isfinite(radii)
        #: the obstacles without a box (half-spaces): every query keeps them
        self.always = np.flatnonzero(~finite)
        boxed = np.flatnonzero(finite)
        #: every obstacle's box (n, 3) each, in the obstacles' order (a half-space's is
        #: the whole space)
        self.lower, self.upper = capsule_boxes(starts, ends, radii)
        self.lower[~finite], self.upper[~finite] = -np.inf, np.inf
        lower, upper = self.lower[boxed], self.upper[boxed]
        order = np.argsort(lower[:, 0], kind="stable")
        self._index = boxed[order]
        self._lower, self._upper = lower[order], upper[order]
        self._widest = float(np.max(upper[:, 0] - lower[:, 0])) if boxed.size else 0.0

    def near(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """A mask (n,) of the obstacles whose box meets ``[low, high]`` (and the
        half-spaces)."""
        mask = np.zeros(self.count, dtype=bool)
        mask[self.always] = True
        column = self._lower[:, 0]
        start = int(np.searchsorted(column, low[0] - self._widest, side="left"))
        stop = int(np.searchsorted(column, high[0], side="right"))
        if stop > start:
            window = slice(start, stop)
            meets = np.all((self._lower[window] <= high) & (self._upper[window] >= low), axis=1)
            mask[self._index[window][meets]] = True
        return mask


def capsule_boxes(starts: np.ndarray, ends: np.ndarray,
                  radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned boxes ``(lower, upper)``, (n, 3) each, of n capsules."""
    radius = radii[:, None]
    return np.minimum(starts, ends) - radius, np.maximum(starts, ends) + radius
