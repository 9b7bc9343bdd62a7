"""The abdominal wall's force on each instrument, drawn at its port as an arrow scaled to
be seen at the forces a drag makes (a few mN; docs/design.md sections 5.3 and 17.2), for
every robot on a physics plant: it points the way the wall pushes the instrument, its tip
on the port's ring (outside the instrument's meshes, which would hide it),
:data:`FORCE_ARROW_SCALE` x ``|F|`` long (the scale is shown in the status line,
:data:`FORCE_ARROW_WORDS`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import viser

from ..app.plant import PortReading
from ..robot_view import RobotView
from .shapes import arrow_segments

#: an arrow's length per newton of wall force (m/N): 2 cm per 10 mN. A 5 cm drag with
#: the drift gain on pushes with 3 mN (6 mm) and peaks near 40 mN (8 cm); the drift gain
#: at 0 leaves about 0.2 N held (40 cm)
FORCE_ARROW_SCALE = 2.0
#: the scale in words, for the status line
FORCE_ARROW_WORDS = "arrow 2 cm per 10 mN"
#: a force below this (N) is drawn as no arrow (its arrow would be under 0.5 mm)
MIN_DRAWN_FORCE = 0.25e-3
FORCE_COLOR = (220, 38, 38)
#: the arrows' width on screen (pixels): seen whatever the zoom
FORCE_ARROW_WIDTH = 5.0


def force_arrow(reading: PortReading, clearance: float = 0.0) -> np.ndarray:
    """Line segments (5, 2, 3) of the arrow of ``reading`` (world, m): along the force,
    :data:`FORCE_ARROW_SCALE` x ``|F|`` long, its tip ``clearance`` m from the port on
    the side the wall pushes from, ``tip = P - clearance u``, ``u = F / |F|``."""
    magnitude = reading.magnitude
    direction = reading.force / magnitude if magnitude > 0 else np.array([0.0, 0.0, 1.0])
    length = FORCE_ARROW_SCALE * magnitude
    tail = reading.point - (clearance + length) * direction
    return arrow_segments(tail, direction, length)


class PortForces:
    """The port-force arrows of :class:`web.ui.TeleopUI`: robot -> port id -> its line
    segments (the ghost's under its own root, moved with it)."""

    server: viser.ViserServer
    _views: dict[str, RobotView]
    ring_radius_at: Callable[[dict], float]
    _port_arrows: dict[str, dict[str, viser.LineSegmentsHandle]]

    def _draw_ports(self, robots: dict) -> None:
        """Each drawn robot's arrows from ``snapshot["robots"]``: one per port its plant
        measured, its tip on the port's ring, hidden below :data:`MIN_DRAWN_FORCE`; none
        without a physics plant."""
        for which in list(self._port_arrows):
            if which not in self._views:  # the ghost went, and its root with its arrows
                self._port_arrows.pop(which)
        for which in self._views:
            arrows = self._port_arrows.setdefault(which, {})
            readings = {reading.id: reading for reading in robots[which]["ports"]}
            for port in [port for port in arrows if port not in readings]:
                arrows.pop(port).remove()
            prefix = "/ports" if which == "main" else "/ghost/ports"
            drawings = robots[which]["constraints"]
            for port, reading in readings.items():
                handle = arrows.get(port)
                shown = reading.magnitude >= MIN_DRAWN_FORCE
                if not shown:  # nothing to compute for an arrow not drawn
                    if handle is not None and handle.visible:
                        handle.visible = False
                    continue
                segments = force_arrow(reading, self.ring_radius_at(drawings[port]))
                if handle is None:
                    arrows[port] = self.server.scene.add_line_segments(
                        f"{prefix}/{port}", segments, FORCE_COLOR,
                        thickness=FORCE_ARROW_WIDTH, thickness_units="screen")
                else:
                    handle.points = segments
                    handle.visible = True
