"""The abdominal wall's force on each instrument, drawn at its port as an arrow whose length
grows with the force's decade, to be seen at every force a session makes (docs/design.md
sections 5.3 and 17.2), for every robot on a physics plant: it points the way the wall
pushes the instrument, its tip on the port's ring (outside the instrument's meshes, which
would hide it), :func:`arrow_length` long: :data:`FORCE_ARROW_PER_DECADE` per tenfold
force above :data:`MIN_DRAWN_FORCE` (the scale is shown in the status line,
:data:`FORCE_ARROW_WORDS`).

The forces of a session span four decades (sda10f, a port on its arm, a 5 cm drag, ``--payload
0.5``: 0.2 mN median during the drag, 52 mN at its peak, 15 mN held with the drift gain
at 0, 1.5 uN at rest): a length in proportion to the force would hide the drag's own
forces or run to metres at its peaks."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection

import numpy as np
import viser

from ..app.plant import PortReading
from .shapes import arrow_segments

#: the arrow's length per tenfold force (m): 2 cm
FORCE_ARROW_PER_DECADE = 0.02
#: a force below this (N) is drawn as no arrow (its arrow would have no length): 10 uN
MIN_DRAWN_FORCE = 1e-5
#: the scale in words, for the status line
FORCE_ARROW_WORDS = "arrow 2 cm at 0.1 mN, 2 cm more per tenfold force"
FORCE_COLOR = (220, 38, 38)
#: the arrows' width on screen (pixels): seen whatever the zoom
FORCE_ARROW_WIDTH = 5.0


def arrow_length(magnitude: float) -> float:
    """The arrow's length (m) for a force of ``magnitude`` N: ``a log10(|F| / F0)`` with
    ``a`` = :data:`FORCE_ARROW_PER_DECADE`, ``F0`` = :data:`MIN_DRAWN_FORCE`; 0 below F0."""
    if not magnitude > MIN_DRAWN_FORCE:
        return 0.0
    return FORCE_ARROW_PER_DECADE * math.log10(magnitude / MIN_DRAWN_FORCE)


def force_arrow(reading: PortReading, clearance: float = 0.0) -> np.ndarray:
    """Line segments (5, 2, 3) of the arrow of ``reading`` (world, m): along the force,
    :func:`arrow_length` long, its tip ``clearance`` m from the port on the side the wall
    pushes from, ``tip = P - clearance u``, ``u = F / |F|``."""
    magnitude = reading.magnitude
    direction = reading.force / magnitude if magnitude > 0 else np.array([0.0, 0.0, 1.0])
    length = arrow_length(magnitude)
    tail = reading.point - (clearance + length) * direction
    return arrow_segments(tail, direction, length)


class PortArrows:
    """The port-force arrows of :class:`web.ui.TeleopUI`, a component owning them:
    :attr:`arrows` maps a robot to its ports' line segments by port id (the ghost's under
    its own root, moved with it). An arrow's tip is on its port's ring,
    ``ring_radius_at(drawing)`` from the port
    (:meth:`web.ui.markers.ConstraintDrawer.ring_radius_at`)."""

    def __init__(self, server: viser.ViserServer,
                 ring_radius_at: Callable[[dict], float]) -> None:
        self.server = server
        self._ring_radius_at = ring_radius_at
        self.arrows: dict[str, dict[str, viser.LineSegmentsHandle]] = {}

    def draw(self, robots: dict, views: Collection[str]) -> None:
        """The arrows of each robot of ``views`` (those drawn) from ``snapshot["robots"]``:
        one per port its plant measured, its tip on the port's ring, hidden below
        :data:`MIN_DRAWN_FORCE`; none without a physics plant."""
        for which in list(self.arrows):
            if which not in views:  # the ghost went, and its root with its arrows
                self.arrows.pop(which)
        for which in views:
            arrows = self.arrows.setdefault(which, {})
            readings = {reading.id: reading for reading in robots[which]["ports"]}
            for port in [port for port in arrows if port not in readings]:
                arrows.pop(port).remove()
            prefix = "/ports" if which == "main" else "/ghost/ports"
            drawings = robots[which]["constraints"]
            for port, reading in readings.items():
                handle = arrows.get(port)
                shown = reading.magnitude > MIN_DRAWN_FORCE
                if not shown:  # nothing to compute for an arrow not drawn
                    if handle is not None and handle.visible:
                        handle.visible = False
                    continue
                clearance = self._ring_radius_at(drawings[port])
                segments = force_arrow(reading, clearance)
                if handle is None:
                    arrows[port] = self.server.scene.add_line_segments(
                        f"{prefix}/{port}", segments, FORCE_COLOR,
                        thickness=FORCE_ARROW_WIDTH, thickness_units="screen")
                else:
                    handle.points = segments
                    handle.visible = True
