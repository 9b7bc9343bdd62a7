"""The Force tab and the contact's drawings (docs/design.md section 21.6): a panel object
holding its viser handles, over :class:`web.app.force_control.ForceControl`.

* the tab: "Place tissue under the tool", "Force control" on/off, the setpoint (N, tool
  frame) and the force-controlled axes (x, y, z of the tool), the contact force in words
  and its plot (the last 10 s at 50 Hz, the setpoint's magnitude dashed);
* in the scene: the tissue as a thin plate (6 cm square, 1 mm thick) on its undeformed surface, and
  the tissue's force on the tool tip as a green arrow along the force, its head on the
  tip, :data:`CONTACT_ARROW_PER_NEWTON` long per newton (hidden below
  :data:`MIN_DRAWN_CONTACT`).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
import pinocchio as pin
import viser
import viser.uplot as uplot

from .plots import X_RANGE, Y_RANGE, axes_labelled
from .shapes import arrow_segments

#: the contact arrow's length per newton (m): 5 cm
CONTACT_ARROW_PER_NEWTON = 0.05
#: a contact force below this (N) draws no arrow
MIN_DRAWN_CONTACT = 1e-3
CONTACT_COLOR = (22, 163, 74)
CONTACT_ARROW_WIDTH = 5.0
TISSUE_COLOR = (244, 114, 182)
#: the plate drawn for the tissue (m): side, thickness
TISSUE_SIDE, TISSUE_THICKNESS = 0.06, 0.001
CONTACT_LINE, SETPOINT_LINE = "#16a34a", "#6b7280"


def contact_arrow(tip: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Line segments (5, 2, 3) of the arrow of the tissue's ``force`` on the tool ``tip``
    (world): along the force, :data:`CONTACT_ARROW_PER_NEWTON` per newton, its head on
    the tip (the tissue pushing it: the arrow lies in the tissue, where no link hides
    it)."""
    magnitude = float(np.linalg.norm(force))
    length = CONTACT_ARROW_PER_NEWTON * magnitude
    return arrow_segments(tip - length * force / magnitude, force / magnitude, length)


class ForcePanel:
    """The Force tab's widgets (built in ``tab``) and the contact's scene handles;
    ``post(event, action, key=)`` hands an operator action to the UI's inbox, ``sync``
    sets widgets without their callbacks acting. The widgets follow the app when its
    settings change, and after an action it refused (they spring back)."""

    def __init__(self, server: viser.ViserServer, tab, force, post: Callable,
                 sync: Callable) -> None:
        self.server, self.tab, self.force, self.sync = server, tab, force, sync
        self._post = post
        self._seen: tuple | None = None  # the app's settings the widgets show
        gui = server.gui
        gui.add_markdown("Press tissue with the tool (the mujoco plant): place it 2 mm "
                         "beyond the tip, then turn force control on; the tool's axes "
                         "chosen below follow the setpoint, the others the gizmo.")
        self.place = gui.add_button("Place tissue under the tool")
        self.enabled = gui.add_checkbox("Force control", False)
        self.setpoint = gui.add_vector3("Setpoint (N, tool)", (0.0, 0.0, 1.0), step=0.1)
        self.axes = [gui.add_checkbox(f"Force along tool {name}", name == "z")
                     for name in "xyz"]
        self.reading = gui.add_markdown("no tissue")
        self.plot: viser.GuiUplotHandle | None = None
        self.tissue: viser.BoxHandle | None = None
        self.arrow: viser.LineSegmentsHandle | None = None
        self.place.on_click(lambda event: self.post(event, force.place_tissue, "force-place"))
        self.enabled.on_update(lambda event: self.post(
            event, partial(force.set_enabled, self.enabled.value), "force-enabled"))
        self.setpoint.on_update(lambda event: self.post(
            event, partial(force.set_setpoint, tuple(self.setpoint.value)), "force-setpoint"))
        for box in self.axes:
            box.on_update(lambda event: self.post(
                event, partial(force.set_axes, [b.value for b in self.axes]), "force-axes"))

    def post(self, event, action: Callable[[], None], key: str) -> None:
        """``action`` (the widgets' values taken now) to the inbox; refused, the widgets
        show the app's settings again."""
        def run() -> None:
            try:
                action()
            except ValueError:
                self._seen = None
                raise

        self._post(event, run, key=key)

    def draw(self, state: dict) -> None:
        """The tissue, the arrow and the words from ``snapshot["force"]``; the widgets
        follow the app (a refused change springs back)."""
        settings = (state["enabled"], tuple(state["setpoint"]), tuple(state["axes"]))
        if settings != self._seen:
            self._seen = settings
            self.sync(lambda: self._widgets_from(state))
        tissue = state["tissue"]
        if tissue is not None:
            point, normal = tissue
            rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), normal)
            wxyz = (rotation.w, rotation.x, rotation.y, rotation.z)
            centre = point - 0.5 * TISSUE_THICKNESS * normal
            if self.tissue is None:
                self.tissue = self.server.scene.add_box(
                    "/force/tissue", TISSUE_COLOR, (TISSUE_SIDE, TISSUE_SIDE, TISSUE_THICKNESS),
                    opacity=0.6, wxyz=wxyz, position=centre)
            else:
                self.tissue.wxyz, self.tissue.position = wxyz, centre
        contact = state["contact"]
        magnitude = float(np.linalg.norm(contact))
        shown = magnitude >= MIN_DRAWN_CONTACT
        if shown:
            segments = contact_arrow(state["tip"], contact)
            if self.arrow is None:
                self.arrow = self.server.scene.add_line_segments(
                    "/force/contact", segments, CONTACT_COLOR, thickness=CONTACT_ARROW_WIDTH,
                    thickness_units="screen")
            else:
                self.arrow.points = segments
                self.arrow.visible = True
        elif self.arrow is not None and self.arrow.visible:
            self.arrow.visible = False
        sensed = -state["sensed"][:3]
        self.reading.content = (
            "no tissue (mujoco plant only)" if tissue is None else
            f"contact force {magnitude:.3f} N (tool pressing: x {sensed[0]:.3f}, "
            f"y {sensed[1]:.3f}, z {sensed[2]:.3f} N sensed); force control "
            f"{'on' if state['enabled'] else 'off'}")

    def draw_plot(self, state: dict, now: float) -> None:
        """The contact force's magnitude over the last 10 s, the setpoint's dashed."""
        history = state["history"]
        if history.shape[0] < 2:
            return
        t = history[:, 0] - now
        magnitude = np.linalg.norm(history[:, 1:], axis=1)
        target = np.full_like(magnitude, float(np.linalg.norm(
            state["setpoint"] * np.asarray(state["axes"], dtype=float))))
        data = (t, magnitude, target)
        if self.plot is not None:
            self.plot.data = data
            return
        with self.tab:
            self.plot = self._add_plot(data)

    def _add_plot(self, data: tuple) -> viser.GuiUplotHandle:
        return self.server.gui.add_uplot(
            data=data, series=(uplot.Series(label="t - now (s)"),
                               uplot.Series(label="contact force", stroke=CONTACT_LINE,
                                            width=1.5),
                               uplot.Series(label="setpoint", stroke=SETPOINT_LINE,
                                            width=1.0, dash=(6.0, 4.0))),
            title="contact force on the tool tip (N)", aspect=2.0,
            scales={"x": uplot.Scale(time=False, auto=False, range=X_RANGE),
                    "y": uplot.Scale(auto=True, range=Y_RANGE)},
            axes=axes_labelled("N"), order=self.reading.order + 0.5)

    def _widgets_from(self, state: dict) -> None:
        if self.enabled.value != state["enabled"]:
            self.enabled.value = state["enabled"]
        setpoint = tuple(float(x) for x in state["setpoint"])
        if tuple(self.setpoint.value) != setpoint:
            self.setpoint.value = setpoint
        for box, axis in zip(self.axes, state["axes"]):
            if box.value != axis:
                box.value = axis
