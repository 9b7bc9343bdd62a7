"""The physics plant's contact pairs follow the ports (docs/design.md section 18.6).

The plant compiles its contact pairs into the MuJoCo model when it is built: every pair of
its collision avoidance (:mod:`teleop.plants.contact_geometry`). A port placed later
exempts the instrument inside it from the obstacles around it
(``CollisionAvoidance.set_ports``), in the controllers and in the loop's distance meter;
the plant follows them. MuJoCo has no switch per contact pair, and a negative margin does
not do it: its capsule and sphere tests then report contacts at any distance (measured
with MuJoCo 4.0). So a pair the avoidance no longer checks points at the two
:data:`~teleop.plants.contact_geometry.PARKING_GEOMS`, a metre apart, and gets its own
geoms back when the port goes.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import mujoco
import numpy as np

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from constraints.collision.ports import is_port

from .contact_geometry import PARKING_GEOMS


class ContactPairs:
    """The plant's contact pairs, each on or off as the avoidance checks it or not.

    ``pairs_by_geoms``: the avoidance's pair each contact pair stands for, by the names of
    its two geoms (what :func:`~teleop.plants.contact_geometry.add_contact_geometry`
    returns).
    """

    def __init__(self, collisions: CollisionAvoidance,
                 pairs_by_geoms: Mapping[frozenset[str], tuple[str, str]],
                 model: mujoco.MjModel) -> None:
        self.collisions = collisions
        self.geoms = np.stack([model.pair_geom1, model.pair_geom2], axis=1).copy()  # own
        #: the avoidance's pair of each contact pair, in the model's order
        self.pair_names = [pairs_by_geoms[frozenset(model.geom(g).name for g in geoms)]
                           for geoms in self.geoms]
        self.parking = [model.geom(name).id for name in PARKING_GEOMS]
        self._ports: tuple | None = None  # the ports last followed, by identity and position
        self._revision = -1  # the avoidance's pairs last applied

    def follow(self, model: mujoco.MjModel, constraints: Sequence[Constraint]) -> None:
        """Switch ``model``'s pairs on or off as the avoidance, with the ports among
        ``constraints``, checks them (nothing to do while the ports stay where they were)."""
        ports = tuple((id(c), *c.position) for c in constraints if is_port(c))
        if ports == self._ports:
            return
        self._ports = ports
        self.collisions.set_ports(constraints)
        if self.collisions.revision == self._revision:
            return
        self._revision = self.collisions.revision
        checked = set(self.collisions.pairs)
        on = np.array([names in checked for names in self.pair_names], dtype=bool)
        model.pair_geom1[:] = np.where(on, self.geoms[:, 0], self.parking[0])
        model.pair_geom2[:] = np.where(on, self.geoms[:, 1], self.parking[1])

    @property
    def switched_off(self) -> list[tuple[str, str]]:
        """The avoidance's pairs whose contacts are off (each once)."""
        checked = set(self.collisions.pairs)
        return list(dict.fromkeys(names for names in self.pair_names if names not in checked))
