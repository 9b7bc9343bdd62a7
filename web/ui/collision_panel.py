"""The Collisions tab's settings (docs/design.md section 18): whether the controllers keep
the pairs apart, self-collision, the damper's d_s, d_i and xi. The obstacles below them
are placed items (:class:`web.ui.placed_panel.PlacedPanel` with an
:class:`web.ui.obstacle_form.ObstacleForm` per kind)."""

from __future__ import annotations

from collections.abc import Callable

import viser

from ..app.collisions import CollisionScene
from .inputs import assign


class CollisionSettingsPanel:
    """The collision settings of :class:`web.ui.TeleopUI`, a component owning its inputs,
    built where the caller's GUI context puts them; each change goes to ``collisions``
    (the session's :class:`web.app.collisions.CollisionScene`) through ``guarded``
    (:meth:`web.ui.TeleopUI._guarded`). Distances are shown in mm, held in m."""

    def __init__(self, gui: viser.GuiApi, collisions: CollisionScene,
                 guarded: Callable[..., None]) -> None:
        self.collisions = collisions
        settings = collisions.settings()
        self.collisions_box = gui.add_checkbox(
            "avoid collisions", settings["on"],
            hint="the controllers keep every pair (link-link, link-obstacle) at least d_s apart")
        self.self_collision_box = gui.add_checkbox(
            "self-collision", settings["self_collision"],
            hint="check the robot's links against each other, not only against the obstacles")
        self.safety_number = gui.add_number(
            "d_s safety distance (mm)", 1e3 * settings["safety_distance"], min=0.0, max=100.0,
            step=0.5, hint="no pair comes closer than this")
        self.detection_number = gui.add_number(
            "d_i detection distance (mm)", 1e3 * settings["detection_distance"], min=1.0,
            max=500.0, step=1.0, hint="a pair closer than this gets its row (and is highlighted)")
        self.approach_number = gui.add_number(
            "xi approach speed (m/s)", settings["approach_speed"], min=0.01, max=5.0,
            step=0.01, hint="how fast a pair may close at d_i (0 at d_s)")
        self.collisions_box.on_update(lambda event: guarded(
            event, lambda: collisions.set_on(self.collisions_box.value), key="collisions"))
        for widget in (self.self_collision_box, self.safety_number, self.detection_number,
                       self.approach_number):
            widget.on_update(lambda event: guarded(
                event, self.apply, key="collision settings", throttled=True))

    def apply(self) -> None:
        """The inputs' settings to the session (d_s, d_i from mm to m)."""
        self.collisions.configure(
            self_collision=bool(self.self_collision_box.value),
            safety_distance=1e-3 * float(self.safety_number.value),
            detection_distance=1e-3 * float(self.detection_number.value),
            approach_speed=float(self.approach_number.value))

    def from_app(self) -> None:
        """The inputs as the session has them (after loading a scene)."""
        settings = self.collisions.settings()
        assign(self.collisions_box, settings["on"])
        assign(self.self_collision_box, settings["self_collision"])
        assign(self.safety_number, 1e3 * settings["safety_distance"])
        assign(self.detection_number, 1e3 * settings["detection_distance"])
        assign(self.approach_number, settings["approach_speed"])
