"""The avoidance rows of one configuration (docs/design.md section 18.3).

For each pair of bodies closer than the detection distance ``d_i``, one velocity damper
(Faverjon and Tournassoud) on the rate of their distance ``d``::

    d_dot >= -xi (d - d_s) / (d_i - d_s) + n . v_obstacle

with ``d_s`` the safety distance and ``xi`` the approach speed allowed at ``d_i``. With
``n`` the unit normal from the second body's witness point to the first's and
``J_1, J_2`` the Jacobians of the witness points (zero for a fixed obstacle),
``d_dot = n^T (J_1 - J_2) qd``: one row ``rows qd >= lower`` per pair.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CollisionRows:
    """``rows qd >= lower``, one row per pair closer than the detection distance.

    Attributes
    ----------
    rows : (m, nv) ``n^T (J_1 - J_2)``, the distance rate's row of each pair.
    lower : (m,) the damper's bound on that rate (m/s), the obstacle's velocity fed forward.
    pairs : (m,) each row's pair, named ``"first | second"`` (link or obstacle names).
    distances : (m,) each pair's distance (m; negative: penetration depth).
    witnesses : (m, 2, 3) the world witness points on the first and the second body.
    minimum_distance : the smallest distance over every pair measured (m); ``inf`` when
        the broadphase found none within the detection distance.
    closest_pair : the pair of :attr:`minimum_distance` ("" when none).
    """

    rows: np.ndarray
    lower: np.ndarray
    pairs: tuple[str, ...]
    distances: np.ndarray
    witnesses: np.ndarray
    minimum_distance: float = float("inf")
    closest_pair: str = ""

    @property
    def size(self) -> int:
        """The number of rows ``m``."""
        return len(self.pairs)

    @classmethod
    def empty(cls, nv: int) -> "CollisionRows":
        """No pair within the detection distance."""
        return cls(np.zeros((0, nv)), np.zeros(0), (), np.zeros(0), np.zeros((0, 2, 3)))

    def violation(self, qd: np.ndarray) -> np.ndarray:
        """``lower - rows qd`` (m,): positive where ``qd`` breaks a row."""
        return self.lower - self.rows @ qd

    def describe(self, index: int) -> str:
        """``"first | second (d = x mm)"``: row ``index``'s pair and distance, for messages."""
        return f"{self.pairs[index]} (d = {1e3 * float(self.distances[index]):.2f} mm)"
