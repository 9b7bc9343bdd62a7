"""The Teleop and Settings tabs: controllers side by side, the console (clutch, motion
scale, the active arm's nudges, home), and the settings (gain, damping, orientation
weight, rate, scenes, recording)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import viser

from teleop.controller_specs import default_specs
from teleop.loop.task_modes import AUTO, TASK_MODES

from ..app import TeleopApp
from .shapes import wxyz_of

CONTROLLER_CHOICES = default_specs("ui")  # the dropdowns (plus a spec given on the command line)
#: the task mode menu (docs/design.md section 20): what the operator reads -> the mode
TASK_MODE_CHOICES = {"what the ports allow (auto)": AUTO,
                     **{mode.words: name for name, mode in TASK_MODES.items()}}
NUDGES = {"-x": (-1, 0, 0), "+x": (1, 0, 0), "-y": (0, -1, 0), "+y": (0, 1, 0),
          "-z": (0, 0, -1), "+z": (0, 0, 1)}


class Panels:
    """The Teleop and Settings tabs of :class:`web.ui.TeleopUI` and the actions that also
    update widgets."""

    server: viser.ViserServer
    app: TeleopApp
    ee_names: dict[str, str]
    target_gizmos: list
    _saved_offset: np.ndarray

    def _build_teleop_panel(self) -> None:
        gui, app = self.server.gui, self.app
        ghost_spec = app.specs.get("ghost", "qp:daqp")
        choices = tuple(dict.fromkeys((*CONTROLLER_CHOICES, app.specs["main"], ghost_spec)))
        self.controller_menu = gui.add_dropdown("main", choices, initial_value=app.specs["main"])
        self.side_by_side = gui.add_checkbox("side by side", "ghost" in app.loops,
                                             hint="a second robot, driven by the ghost "
                                                  "controller from the same target")
        self.ghost_menu = gui.add_dropdown("ghost", choices, initial_value=ghost_spec)
        self.ghost_offset = gui.add_vector3("ghost offset (m)", tuple(app.ghost_offset), step=0.05,
                                            hint="where the ghost is drawn from the main robot, "
                                                 "world coordinates")
        self.overlay = gui.add_checkbox("overlay", bool(np.linalg.norm(app.ghost_offset) < 1e-9),
                                        hint="draw the ghost on the main robot (offset 0)")
        self.clutch_button = gui.add_button("Clutch", hint="engaged: moving the gizmo does not "
                                            "move the target; released: the target continues "
                                            "from where it is")
        self.motion_scale = gui.add_number("motion scale", app.motion_scale, min=0.01,
                                           max=10.0, step=0.05,
                                           hint="target displacement per gizmo displacement")
        names = tuple(self.ee_names.values())
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
            "command", tuple(TASK_MODE_CHOICES), initial_value=self._task_mode_label(),
            hint="what the target asks of each end effector; auto: position and roll "
                 "about the tool axis with a port on the arm (what a port allows), else "
                 "the full pose; the rest is left to the joints' free motion")

        self.controller_menu.on_update(lambda event: self._guarded(
            event, lambda: app.set_controller(self.controller_menu.value), key="controller",
            throttled=True))
        self.side_by_side.on_update(lambda event: self._guarded(event, lambda: app.set_ghost(
            self.ghost_menu.value if self.side_by_side.value else None), key="ghost",
            throttled=True))
        self.ghost_menu.on_update(lambda event: self._guarded(event, lambda: (
            app.set_ghost(self.ghost_menu.value) if self.side_by_side.value else None),
            key="ghost", throttled=True))
        self.ghost_offset.on_update(lambda event: self._guarded(event, self._offset_changed,
                                                                key="ghost offset"))
        self.overlay.on_update(lambda event: self._guarded(event, self._overlay_changed,
                                                           key="ghost offset"))
        self.clutch_button.on_click(lambda event: self._guarded(
            event, lambda: app.set_clutch(not app.clutch)))
        self.motion_scale.on_update(lambda event: self._guarded(
            event, lambda: app.set_motion_scale(self.motion_scale.value), key="motion scale"))
        self.nudge_buttons.on_click(lambda event: self._guarded(event, self._nudge))
        self.gizmo_button.on_click(lambda event: self._guarded(event, self._gizmo_to_target))
        self.home_button.on_click(lambda event: self._guarded(event, self._home))
        self.task_mode_menu.on_update(lambda event: self._guarded(
            event, lambda: app.set_task_mode(TASK_MODE_CHOICES[self.task_mode_menu.value]),
            key="task mode"))

    def _task_mode_label(self) -> str:
        """The menu's label of the session's task mode."""
        return next(label for label, mode in TASK_MODE_CHOICES.items()
                    if mode == self.app.task_mode)

    def _build_settings_panel(self) -> None:
        gui, app = self.server.gui, self.app
        self.gain_slider = gui.add_slider("drift gain K (1/s)", 0.0, 500.0, 5.0, app.gain)
        self.damping_slider = gui.add_slider("damping lambda", 0.0, 0.2, 0.001, app.damping)
        self.orientation_slider = gui.add_slider(
            "orientation weight", 0.0, 1.0, 0.05, app.orientation_weight,
            hint="weight of the tools' orientations against their tip positions: lower it "
                 "when two trocars on one torso leave too few joints for both full poses")
        self.rate_number = gui.add_number("rate (Hz)", app.config.rate, min=50, max=5000, step=50)
        self.scene_path = gui.add_text(
            "scene name", "scene.json",
            hint=f"a file name in the scene folder ({app.scenes.root.name}/, set by `teleop "
                 "web --scene-dir`): no folders, nothing outside it")
        self.save_scene_button = gui.add_button("Save scene")
        self.load_scene_button = gui.add_button("Load scene")
        self.scene_status = gui.add_markdown("")
        self.record_button = gui.add_button("Start recording")
        self.record_status = gui.add_markdown("not recording")

        self.gain_slider.on_update(lambda event: self._guarded(
            event, lambda: app.set_gain(self.gain_slider.value), key="gain", throttled=True))
        self.damping_slider.on_update(lambda event: self._guarded(
            event, lambda: app.set_damping(self.damping_slider.value), key="damping"))
        self.orientation_slider.on_update(lambda event: self._guarded(
            event, lambda: app.set_orientation_weight(self.orientation_slider.value),
            key="orientation weight", throttled=True))
        self.rate_number.on_update(lambda event: self._guarded(
            event, lambda: app.set_rate(self.rate_number.value), key="rate", throttled=True))
        self.save_scene_button.on_click(lambda event: self._guarded(
            event, self._save_scene, throttled=True))
        self.load_scene_button.on_click(lambda event: self._guarded(
            event, self._load_scene, throttled=True))
        self.record_button.on_click(lambda event: self._guarded(event, self._toggle_recording))

    def _active_ee(self) -> int:
        """The index (in ``robot.ee_frames``) of the arm chosen as active."""
        return list(self.ee_names.values()).index(self.active_arm.value)

    def _move_gizmo_handle(self, pose: pin.SE3, ee: int = 0) -> None:
        self.target_gizmos[ee].position = pose.translation
        self.target_gizmos[ee].wxyz = wxyz_of(pose.rotation)

    def _move_gizmo_handles(self) -> None:
        """Every gizmo handle where the app's gizmo is."""
        for index, hand in enumerate(self.app.inputs):
            self._move_gizmo_handle(hand.gizmo, index)

    def _home(self) -> None:
        words = self.app.home()
        self._move_gizmo_handles()
        if words:  # home cannot be reached through the constraints: say why
            self.notify(None, "Home not reachable", words, color="yellow")

    def _nudge(self) -> None:
        """The active arm's target moved by the nudge step along the button's axis, its
        gizmo following (on the target: the next drag starts where the nudge left it)."""
        ee = self._active_ee()
        self.app.nudge_target(
            self.nudge_step.value * np.asarray(NUDGES[self.nudge_buttons.value], dtype=float), ee)
        self._move_gizmo_handle(self.app.gizmo_to_target(ee), ee)

    def _gizmo_to_target(self) -> None:
        ee = self._active_ee()
        self._move_gizmo_handle(self.app.gizmo_to_target(ee), ee)

    def _offset_changed(self) -> None:
        self.app.set_ghost_offset(np.asarray(self.ghost_offset.value, dtype=float))
        overlay = float(np.linalg.norm(self.app.ghost_offset)) < 1e-9
        if not overlay:
            self._saved_offset = self.app.ghost_offset.copy()
        self._sync(lambda: setattr(self.overlay, "value", overlay))

    def _overlay_changed(self) -> None:
        offset = np.zeros(3) if self.overlay.value else self._saved_offset
        self.app.set_ghost_offset(offset)
        self._sync(lambda: setattr(self.ghost_offset, "value", tuple(float(x) for x in offset)))

    def _save_scene(self) -> None:
        path = self.app.save_scene(self.scene_path.value)
        self.scene_status.content = f"saved `{path.name}`"

    def _load_scene(self) -> None:
        name = self.scene_path.value
        self.app.load_scene(name)
        self._sync(self._widgets_from_app)
        self._sync(self.collision_settings.from_app)
        self.obstacle_markers.remove()
        self._move_gizmo_handles()
        self.scene_status.content = f"loaded `{self.app.scenes.name_of(name)}`"

    def _widgets_from_app(self) -> None:
        app = self.app
        choices = tuple(self.controller_menu.options)
        for menu, spec in ((self.controller_menu, app.specs["main"]),
                           (self.ghost_menu, app.specs.get("ghost"))):
            if spec is None:
                continue
            if spec not in choices:
                choices = (*choices, spec)
                self.controller_menu.options = self.ghost_menu.options = choices
            menu.value = spec
        self.side_by_side.value = "ghost" in app.loops
        self.ghost_offset.value = tuple(float(x) for x in app.ghost_offset)
        self.overlay.value = bool(np.linalg.norm(app.ghost_offset) < 1e-9)
        if not self.overlay.value:
            self._saved_offset = app.ghost_offset.copy()
        self.motion_scale.value = app.motion_scale
        self.gain_slider.value = app.gain
        self.damping_slider.value = app.damping
        self.orientation_slider.value = app.orientation_weight
        self.task_mode_menu.value = self._task_mode_label()
        self.rate_number.value = app.config.rate

    def _toggle_recording(self) -> None:
        if not self.app.recorder.active:
            path = self.app.start_recording()
            self.record_button.label = "Stop recording"
            self.record_status.content = f"recording to `{path.name}`"
        else:
            path = self.app.stop_recording()
            self.record_button.label = "Start recording"
            self.record_status.content = f"wrote `{path}` (replay: `teleop replay {path}`)"
