"""The Teleop tab: the controllers side by side (the ghost, its offset, overlaid or
beside) and the console (clutch, motion scale, the active arm's nudges, "Gizmo to
target", home, what the target asks of each end effector)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin
import viser

from teleop.controller_specs import default_specs
from teleop.loop.task_modes import AUTO, TASK_MODES

from ..app import TeleopApp
from .inputs import assign

CONTROLLER_CHOICES = default_specs("ui")  # the dropdowns (plus a spec given on the command line)
#: the task mode menu (docs/design.md section 20): what the operator reads -> the mode
TASK_MODE_CHOICES = {"what the ports allow (auto)": AUTO,
                     **{mode.words: name for name, mode in TASK_MODES.items()}}
NUDGES = {"-x": (-1, 0, 0), "+x": (1, 0, 0), "-y": (0, -1, 0), "+y": (0, 1, 0),
          "-z": (0, 0, -1), "+z": (0, 0, 1)}


def task_mode_label(mode: str) -> str:
    """The menu's label of task mode ``mode``."""
    return next(label for label, choice in TASK_MODE_CHOICES.items() if choice == mode)


class TeleopPanel:
    """The Teleop tab of :class:`web.ui.TeleopUI`, a component owning its inputs, built
    where the caller's GUI context puts them. Each action goes through ``guarded``
    (:meth:`web.ui.TeleopUI._guarded`); ``sync(action)`` sets inputs without their
    callbacks acting; ``move_gizmo(pose, ee)`` puts EE ``ee``'s gizmo handle at ``pose``;
    ``notify`` tells the browsers (``notify(None, title, body, color=...)``)."""

    def __init__(self, gui: viser.GuiApi, app: TeleopApp, ee_names: dict[str, str],
                 guarded: Callable[..., None], sync: Callable[[Callable[[], None]], None],
                 move_gizmo: Callable[[pin.SE3, int], None],
                 notify: Callable[..., None]) -> None:
        self.app = app
        self.ee_names = ee_names
        self._sync = sync
        self._move_gizmo = move_gizmo
        self._notify = notify
        #: the ghost's offset before "overlay" put it at zero (where unticking puts it back)
        self._saved_offset = app.robots.ghost_offset.copy()
        ghost_spec = app.robots.specs.get("ghost", "qp:daqp")
        choices = tuple(dict.fromkeys((*CONTROLLER_CHOICES, app.robots.specs["main"], ghost_spec)))
        self.controller_menu = gui.add_dropdown("main", choices, initial_value=app.robots.specs["main"])
        self.side_by_side = gui.add_checkbox("side by side", "ghost" in app.robots.loops,
                                             hint="a second robot, driven by the ghost "
                                                  "controller from the same target")
        self.ghost_menu = gui.add_dropdown("ghost", choices, initial_value=ghost_spec)
        self.ghost_offset = gui.add_vector3("ghost offset (m)", app.robots.ghost_offset, step=0.05,
                                            hint="where the ghost is drawn from the main robot, "
                                                 "world coordinates")
        self.overlay = gui.add_checkbox("overlay", bool(np.linalg.norm(app.robots.ghost_offset) < 1e-9),
                                        hint="draw the ghost on the main robot (offset 0)")
        self.clutch_button = gui.add_button("Clutch", hint="engaged: moving the gizmo does not "
                                            "move the target; released: the target continues "
                                            "from where it is")
        self.motion_scale = gui.add_number("motion scale", app.console.motion_scale, min=0.01,
                                           max=10.0, step=0.05,
                                           hint="target displacement per gizmo displacement")
        names = tuple(ee_names.values())
        self.active_arm = gui.add_dropdown(
            "active arm", names, initial_value=names[0], visible=len(names) > 1,
            hint="the end effector the nudges and 'Gizmo to target' act on (each gizmo "
                 "drives its own)")
        self.nudge_step = gui.add_number("nudge step (m)", 0.005, min=0.0005, max=0.1,
                                         step=0.0005)
        self.nudge_buttons = gui.add_button_group("nudge target", tuple(NUDGES))
        self.gizmo_button = gui.add_button("Gizmo to target")
        self.home_button = gui.add_button("Home", hint="the robot home through the "
                                          "constraints (they stay), or why it cannot")
        self.task_mode_menu = gui.add_dropdown(
            "command", tuple(TASK_MODE_CHOICES), initial_value=task_mode_label(app.robots.task_mode),
            hint="what the target asks of each end effector; auto: position and roll "
                 "about the tool axis with a port on the arm (what a port allows), else "
                 "the full pose; the rest is left to the joints' free motion")

        self.controller_menu.on_update(lambda event: guarded(
            event, lambda: app.robots.set_controller(self.controller_menu.value), key="controller",
            throttled=True))
        self.side_by_side.on_update(lambda event: guarded(event, lambda: app.robots.set_ghost(
            self.ghost_menu.value if self.side_by_side.value else None), key="ghost",
            throttled=True))
        self.ghost_menu.on_update(lambda event: guarded(event, lambda: (
            app.robots.set_ghost(self.ghost_menu.value) if self.side_by_side.value else None),
            key="ghost", throttled=True))
        self.ghost_offset.on_update(lambda event: guarded(event, self._offset_changed,
                                                          key="ghost offset"))
        self.overlay.on_update(lambda event: guarded(event, self._overlay_changed,
                                                     key="ghost offset"))
        self.clutch_button.on_click(lambda event: guarded(
            event, lambda: app.console.set_clutch(not app.console.clutch)))
        self.motion_scale.on_update(lambda event: guarded(
            event, lambda: app.console.set_motion_scale(self.motion_scale.value), key="motion scale"))
        self._guarded = guarded
        self.nudge_buttons.on_click(self.nudge_clicked)
        self.gizmo_button.on_click(lambda event: guarded(event, self.gizmo_to_target))
        self.home_button.on_click(lambda event: guarded(event, self.home))
        self.task_mode_menu.on_update(lambda event: guarded(
            event, lambda: app.robots.set_task_mode(TASK_MODE_CHOICES[self.task_mode_menu.value]),
            key="task mode"))

    def active_ee(self) -> int:
        """The index (in ``robot.ee_frames``) of the arm chosen as active."""
        return list(self.ee_names.values()).index(self.active_arm.value)

    def home(self) -> None:
        """Every EE home through the constraints, the gizmos following; why not, if not."""
        words = self.app.console.home()
        for index, hand in enumerate(self.app.console.inputs):
            self._move_gizmo(hand.gizmo, index)
        if words:  # home cannot be reached through the constraints: say why
            self._notify(None, "Home not reachable", words, color="yellow")

    async def nudge_clicked(self, event: viser.GuiEvent) -> None:
        """A click on a nudge button: the nudge it asks for (its button, the step and the
        active arm, read now) posted to the inbox. A coroutine, which viser awaits in its
        event loop as the click's message arrives: a plain callback runs later on viser's
        thread pool, and the inbox later still, when a second click may have changed the
        group's value (on a busy machine "+y" then "-z" nudged -z twice)."""
        nudge = (NUDGES[self.nudge_buttons.value], self.nudge_step.value, self.active_ee())
        self._guarded(event, lambda: self.nudge(*nudge))

    def nudge(self, direction: tuple[int, int, int], step: float, ee: int) -> None:
        """EE ``ee``'s target moved by ``step`` (m) along ``direction``, its gizmo following
        (on the target: the next drag starts where the nudge left it)."""
        self.app.console.nudge_target(step * np.asarray(direction, dtype=float), ee)
        self._move_gizmo(self.app.console.gizmo_to_target(ee), ee)

    def gizmo_to_target(self) -> None:
        """The active arm's gizmo put on its target."""
        ee = self.active_ee()
        self._move_gizmo(self.app.console.gizmo_to_target(ee), ee)

    def _offset_changed(self) -> None:
        self.app.robots.set_ghost_offset(np.asarray(self.ghost_offset.value, dtype=float))
        overlay = float(np.linalg.norm(self.app.robots.ghost_offset)) < 1e-9
        if not overlay:
            self._saved_offset = self.app.robots.ghost_offset.copy()
        self._sync(lambda: assign(self.overlay, overlay))

    def _overlay_changed(self) -> None:
        offset = np.zeros(3) if self.overlay.value else self._saved_offset
        self.app.robots.set_ghost_offset(offset)
        self._sync(lambda: assign(self.ghost_offset, (float(offset[0]), float(offset[1]),
                                                      float(offset[2]))))

    def show_clutch(self, clutch: bool) -> None:
        """The clutch button says what a click does."""
        label = "Release clutch" if clutch else "Clutch"
        if self.clutch_button.label != label:
            self.clutch_button.label = label

    def from_app(self) -> None:
        """The inputs as the app has them (after loading a scene); a controller spec not
        among the menus' choices added to them."""
        app = self.app
        choices = tuple(self.controller_menu.options)
        for menu, spec in ((self.controller_menu, app.robots.specs["main"]),
                           (self.ghost_menu, app.robots.specs.get("ghost"))):
            if spec is None:
                continue
            if spec not in choices:
                choices = (*choices, spec)
                self.controller_menu.options = self.ghost_menu.options = choices
            assign(menu, spec)
        assign(self.side_by_side, "ghost" in app.robots.loops)
        offset = app.robots.ghost_offset
        assign(self.ghost_offset, (float(offset[0]), float(offset[1]), float(offset[2])))
        assign(self.overlay, bool(np.linalg.norm(offset) < 1e-9))
        if not self.overlay.value:
            self._saved_offset = offset.copy()
        assign(self.motion_scale, app.console.motion_scale)
        assign(self.task_mode_menu, task_mode_label(app.robots.task_mode))
