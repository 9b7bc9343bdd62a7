"""The Collisions tab (docs/design.md section 18): whether the controllers keep the pairs
apart, self-collision, the damper's d_s, d_i and xi; per obstacle kind of the registry
(:data:`constraints.collision.OBSTACLE_TYPES`) a folder with an input per field of its
constructor and an "Add <label>" button (placed in front of the active arm's tip); the
placed obstacles, "Remove" and "Clear obstacles"; the pairs held. No kind is named here."""

from __future__ import annotations

import numpy as np
import viser

from constraints.collision import OBSTACLE_TYPES

from ..app import TeleopApp
from ..app.collisions import obstacle_fields

#: what an empty menu shows
NONE = "(none)"


class CollisionPanel:
    """The Collisions tab of :class:`web.ui.TeleopUI`. ``obstacle_inputs[kind][field]``
    is the input of one field of one kind."""

    server: viser.ViserServer
    app: TeleopApp
    obstacle_inputs: dict[str, dict[str, object]]

    def _build_collision_panel(self) -> None:
        gui, app = self.server.gui, self.app
        settings = app.collisions.settings()
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
        self.collisions_box.on_update(lambda event: self._guarded(
            event, lambda: app.collisions.set_on(self.collisions_box.value), key="collisions"))
        for widget in (self.self_collision_box, self.safety_number, self.detection_number,
                       self.approach_number):
            widget.on_update(lambda event: self._guarded(
                event, self._apply_collision_settings, key="collision settings", throttled=True))
        self.obstacle_inputs = {}
        for kind, kind_type in OBSTACLE_TYPES.items():
            with gui.add_folder(f"{kind_type.label} obstacle", expand_by_default=False):
                inputs = {name: self._add_obstacle_input(kind_type.label, name, default)
                          for name, default in obstacle_fields(kind).items()}
                button = gui.add_button(f"Add {kind_type.label}",
                                        hint="placed in front of the active arm's tip; "
                                             "drag its gizmo to move it")
            self.obstacle_inputs[kind] = inputs
            button.on_click(lambda event, kind=kind: self._guarded(
                event, lambda: self._add_obstacle_from_inputs(kind)))
        self.obstacle_menu = gui.add_dropdown("obstacles", (NONE,))
        remove = gui.add_button("Remove obstacle")
        clear = gui.add_button("Clear obstacles")
        remove.on_click(lambda event: self._guarded(
            event, lambda: app.collisions.remove(self.obstacle_menu.value)))
        clear.on_click(lambda event: self._guarded(event, app.collisions.clear))

    def _add_obstacle_input(self, label: str, name: str, default):
        """The input of one constructor field, labelled "<kind label> <field>"."""
        gui, text = self.server.gui, f"{label} {name}"
        if np.ndim(default) == 1:
            return gui.add_vector3(text, tuple(float(x) for x in default), step=0.01)
        return gui.add_number(text, float(default), min=0.0, step=0.005)

    def _add_obstacle_from_inputs(self, kind: str) -> str:
        values = {name: np.asarray(widget.value, dtype=float) if np.ndim(widget.value)
                  else float(widget.value)
                  for name, widget in self.obstacle_inputs[kind].items()}
        return self.app.collisions.add(kind, ee=self._active_ee(), **values)

    def _apply_collision_settings(self) -> None:
        self.app.collisions.configure(
            self_collision=bool(self.self_collision_box.value),
            safety_distance=1e-3 * float(self.safety_number.value),
            detection_distance=1e-3 * float(self.detection_number.value),
            approach_speed=float(self.approach_number.value))

    def _collision_widgets_from_app(self) -> None:
        """The tab's settings as the app has them (after loading a scene)."""
        settings = self.app.collisions.settings()
        self.collisions_box.value = settings["on"]
        self.self_collision_box.value = settings["self_collision"]
        self.safety_number.value = 1e3 * settings["safety_distance"]
        self.detection_number.value = 1e3 * settings["detection_distance"]
        self.approach_number.value = settings["approach_speed"]

    def _list_obstacles(self, ids: tuple[str, ...]) -> None:
        """The "obstacles" menu lists ``ids`` (or says none)."""
        options = ids or (NONE,)
        if tuple(self.obstacle_menu.options) != options:
            self.obstacle_menu.options = options
