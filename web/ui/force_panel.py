"""The Force tab and the contact's drawings (docs/design.md section 21.6): a panel object
holding its viser handles, over :class:`web.app.force_control.ForceControl`.

* the tab: "Place tissue under the tool", "Force control" on/off, the setpoint (N, tool
  frame) and the force-controlled axes (x, y, z of the tool), the contact force in words
  and its plot (the last 10 s at 50 Hz, the setpoint's magnitude dashed);
* in the scene: the tissue as a thin plate (6 cm square, 1 mm thick) on its undeformed surface, and
  the tissue's force on the tool tip as a green arrow along the force, its head on the
  tip, :data:`CONTACT_ARROW_PER_NEWTON` long per newton (hidden below
  :data:`MIN_DRAWN_CONTACT`); for every robot drawn, the ghost's (its own plant presses
  the same tissue) under ``/ghost``, beside the main robot with it.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from functools import partial

import numpy as np
import pinocchio as pin
import viser
import viser.uplot as uplot

from .inputs import assign
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
        #: per robot drawn (``main``, ``ghost``): its tissue plate and its contact arrow
        self.tissues: dict[str, viser.BoxHandle] = {}
        self.arrows: dict[str, viser.LineSegmentsHandle] = {}
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

    @property
    def arrow(self) -> viser.LineSegmentsHandle | None:
        """The main robot's contact arrow (None before one was drawn)."""
        return self.arrows.get("main")

    def draw(self, state: dict, drawn: Collection[str] = ("main",)) -> None:
        """The tissue, the arrows and the words from ``snapshot["force"]``, for each robot
        of ``drawn`` (the ghost's under ``/ghost``, its root; its handles are forgotten
        when it goes, with the root); the widgets follow the app (a refused change springs
        back)."""
        settings = (state["enabled"], tuple(state["setpoint"]), tuple(state["axes"]))
        if settings != self._seen:
            self._seen = settings
            self.sync(lambda: self._widgets_from(state))
        for handles in (self.tissues, self.arrows):
            for which in [which for which in handles if which not in drawn]:
                handles.pop(which)
        tissue = state["tissue"]
        for which, contact in state["contacts"].items():
            if which not in drawn:
                continue
            prefix = "/force" if which == "main" else f"/{which}/force"
            if tissue is not None:
                self._draw_tissue(which, prefix, *tissue)
            self._draw_arrow(which, prefix, contact["tip"], contact["contact"])
        magnitude = float(np.linalg.norm(state["contact"]))
        sensed = -state["sensed"][:3]
        self.reading.content = (
            "no tissue (mujoco plant only)" if tissue is None else
            f"contact force {magnitude:.3f} N (tool pressing: x {sensed[0]:.3f}, "
            f"y {sensed[1]:.3f}, z {sensed[2]:.3f} N sensed); force control "
            f"{'on' if state['enabled'] else 'off'}")

    def _draw_tissue(self, which: str, prefix: str, point: np.ndarray,
                     normal: np.ndarray) -> None:
        """Robot ``which``'s tissue plate (under ``prefix``) on the undeformed surface."""
        rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), normal)
        wxyz = (rotation.w, rotation.x, rotation.y, rotation.z)
        centre = point - 0.5 * TISSUE_THICKNESS * normal
        plate = self.tissues.get(which)
        if plate is None:
            self.tissues[which] = self.server.scene.add_box(
                f"{prefix}/tissue", TISSUE_COLOR, (TISSUE_SIDE, TISSUE_SIDE, TISSUE_THICKNESS),
                opacity=0.6, wxyz=wxyz, position=centre)
        else:
            plate.wxyz, plate.position = wxyz, centre

    def _draw_arrow(self, which: str, prefix: str, tip: np.ndarray,
                    contact: np.ndarray) -> None:
        """Robot ``which``'s contact arrow (under ``prefix``), hidden below
        :data:`MIN_DRAWN_CONTACT`."""
        arrow = self.arrows.get(which)
        if float(np.linalg.norm(contact)) < MIN_DRAWN_CONTACT:
            if arrow is not None and arrow.visible:
                arrow.visible = False
            return
        segments = contact_arrow(tip, contact)
        if arrow is None:
            self.arrows[which] = self.server.scene.add_line_segments(
                f"{prefix}/contact", segments, CONTACT_COLOR, thickness=CONTACT_ARROW_WIDTH,
                thickness_units="screen")
        else:
            arrow.points = segments
            arrow.visible = True

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
            assign(self.enabled, state["enabled"])
        x, y, z = (float(value) for value in state["setpoint"])
        if tuple(self.setpoint.value) != (x, y, z):
            assign(self.setpoint, (x, y, z))
        for box, axis in zip(self.axes, state["axes"]):
            if box.value != axis:
                assign(box, axis)
