"""The 3D scene: the robot (and its ghost), the grid, per end effector an input gizmo, its
target and the line from the EE to it in the step status's colour; a browser lost
mid-drag holds its target where the robot is (docs/design.md section 5.3)."""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin
import viser

from ..app import TeleopApp, default_ghost_offset
from ..inbox import Inbox
from ..robot_view import RobotView
from .placed_markers import PlacedMarkers
from .plots import LivePlots
from .shapes import wxyz_of

#: the target gizmo's size (m): its handles large enough to grab from the first view
#: (1 m away) rather than orbit the camera
GIZMO_SCALE = 0.16
#: each gizmo's size (m) on a robot with several EEs, whose tools are close together:
#: larger gizmos would cover each other
GIZMO_SCALE_SEVERAL = 0.12
GHOST_PLOTS_FIRST = 0.5  # s: a new ghost is drawn once the plots show it, or after this
GHOST_RGBA = (0.45, 0.7, 1.0, 0.8)  # beside the main robot
GHOST_OVERLAY_RGBA = (0.25, 0.5, 0.95, 0.4)  # on it: see-through
#: the EE-target line's colour for each step status
STATUS_COLORS = {"ok": (30, 160, 70), "scaled": (230, 170, 0), "least_squares": (240, 110, 0),
                 "constraint_degraded": (220, 30, 30), "failed": (150, 0, 150)}


class SceneView:
    """The robots, gizmos and targets of :class:`web.ui.TeleopUI`."""

    server: viser.ViserServer
    app: TeleopApp
    inbox: Inbox
    floor: float
    _views: dict[str, RobotView]
    _ghost_root: object
    _ghost_style: tuple | None
    _ghost_seen: float | None
    ghost_markers: PlacedMarkers
    _line_colors: dict[tuple[str, int], tuple]
    _port_arrows: dict[str, dict]
    _gone: set[int]
    plots: LivePlots

    def _build_scene(self) -> None:
        scene = self.server.scene
        self.grid = scene.add_grid("/grid", width=4.0, height=4.0, cell_size=0.1,
                                   section_size=0.5, position=(0.0, 0.0, self.floor))
        self._views["main"] = RobotView(self.app.robot, self.server, "/main")
        # per EE: its gizmo, its target (drawn where it is apart from the gizmo), the line
        # from the EE to the target; the first EE's keep the single-EE names
        self.target_gizmos, self.target_markers, self.reach_lines = [], [], []
        size = GIZMO_SCALE if len(self.app.targets) == 1 else GIZMO_SCALE_SEVERAL
        for index, target in enumerate(self.app.targets):
            suffix = "" if index == 0 else f"_{index}"
            gizmo = scene.add_transform_controls(
                f"/gizmo{suffix}", scale=size, line_width=4.0,
                position=target.translation,
                wxyz=wxyz_of(target.rotation))
            gizmo.on_update(self._gizmo_moved(gizmo, index))
            self.target_gizmos.append(gizmo)
            self.target_markers.append(scene.add_frame(
                f"/target{suffix}", axes_length=0.05, axes_radius=0.004, origin_radius=0.008,
                visible=False))
            self.reach_lines.append(scene.add_line_segments(
                f"/reach{suffix}", np.zeros((1, 2, 3)), STATUS_COLORS["ok"], thickness=4.0,
                thickness_units="screen"))
        self.target_gizmo, self.target_marker = self.target_gizmos[0], self.target_markers[0]
        self.reach_line = self.reach_lines[0]
        # every new browser looks at the tools from the front (where the arms reach), the
        # ghost to the left of the main robot (clear of the control panel, on the right)
        side = default_ghost_offset(self.app.robot)
        side /= np.linalg.norm(side)
        front = np.cross([0.0, 0.0, 1.0], side)
        look_at = np.mean([target.translation for target in self.app.targets], axis=0)
        distance = 1.0
        if "ghost" in self.app.robots.loops:
            look_at += 0.5 * self.app.robots.ghost_offset
            distance += 0.8 * float(np.linalg.norm(self.app.robots.ghost_offset))
        direction = 0.8 * front + 0.3 * side + np.array([0.0, 0.0, 0.5])
        self.server.initial_camera.position = look_at + distance * direction / np.linalg.norm(direction)
        self.server.initial_camera.look_at = look_at

    def _gizmo_moved(self, gizmo, index: int):
        """The callback of EE ``index``'s gizmo: the app moves that EE's target, the
        latest pose winning. A drag that viser ends because its browser went away holds
        the target where the robot is (:meth:`TeleopApp.hold_where_the_robot_is`)."""
        def moved(event) -> None:
            client = event.client_id
            if client is not None and client not in self.server.get_clients():
                if event.phase == "end":
                    self._lost_mid_drag(client, index)
                return
            position, wxyz = np.array(gizmo.position), np.array(gizmo.wxyz)
            self._guarded(event, lambda: None if client in self._gone else
                          self.app.move_gizmo(position, wxyz, index), key=("gizmo", index))
        return moved

    def _lost_mid_drag(self, client: int, index: int) -> None:
        """Browser ``client`` disconnected while dragging EE ``index``'s gizmo: its moves
        still pending are dropped, the target held where the EE is, the handle put there
        for the other browsers."""
        self._gone.add(client)

        def hold() -> None:
            self.app.hold_where_the_robot_is(index)
            self._move_gizmo_handle(self.app.inputs[index].gizmo, index)

        self.inbox.post(hold, key=("hold", index))

    def _move_gizmo_handle(self, pose: pin.SE3, ee: int = 0) -> None:
        """EE ``ee``'s gizmo handle put at ``pose`` (for every browser)."""
        self.target_gizmos[ee].position = pose.translation
        self.target_gizmos[ee].wxyz = wxyz_of(pose.rotation)

    def _move_gizmo_handles(self) -> None:
        """Every gizmo handle where the app's gizmo is."""
        for index, hand in enumerate(self.app.inputs):
            self._move_gizmo_handle(hand.gizmo, index)

    def _ghost_rgba(self) -> tuple[float, float, float, float]:
        overlay = float(np.linalg.norm(self.app.robots.ghost_offset)) < 1e-9
        return GHOST_OVERLAY_RGBA if overlay else GHOST_RGBA

    def _add_ghost(self, offset: np.ndarray) -> None:
        scene = self.server.scene
        self._ghost_root = scene.add_frame("/ghost", show_axes=False, position=offset)
        rgba = self._ghost_rgba()
        self._views["ghost"] = RobotView(self.app.robot, self.server, "/ghost/robot", color=rgba)
        self._ghost_style = rgba
        self.ghost_targets, self.ghost_reaches = [], []
        for index in range(len(self.app.robot.ee_frames)):
            suffix = "" if index == 0 else f"_{index}"
            self.ghost_targets.append(scene.add_frame(
                f"/ghost/target{suffix}", axes_length=0.05, axes_radius=0.004,
                origin_radius=0.008))
            self.ghost_reaches.append(scene.add_line_segments(
                f"/ghost/reach{suffix}", np.zeros((1, 2, 3)), STATUS_COLORS["ok"],
                thickness=4.0, thickness_units="screen"))
        self.ghost_target, self.ghost_reach = self.ghost_targets[0], self.ghost_reaches[0]

    def _remove_ghost(self) -> None:
        for key in [key for key in self._line_colors if key[0] == "ghost"]:
            self._line_colors.pop(key)
        if self._ghost_root is not None:
            self._ghost_root.remove()  # and every node under /ghost
        self._ghost_root = None
        self._views.pop("ghost", None)
        self.ghost_markers.forget()  # its nodes removed with the root
        self._port_arrows.pop("ghost", None)  # removed with the root

    def _ghost_due(self) -> bool:
        """Whether to draw a ghost that just joined: once the plots show it (or after
        GHOST_PLOTS_FIRST s). A browser compiles the shaders of new meshes on their first
        frame, which holds a software-rendered page for seconds: the plots go first."""
        now = time.perf_counter()
        if self._ghost_seen is None:
            self._ghost_seen = now
        return ("ghost" in self.plots.plotted or now - self._ghost_seen > GHOST_PLOTS_FIRST)

    def _draw_target(self, snapshot: dict) -> None:
        """Per EE: its target (where apart from its gizmo, or clutched) and, per robot, the
        line from the EE to it in the step status's colour."""
        ghost = "ghost" in self._views
        for index, (target, gizmo) in enumerate(zip(snapshot["targets"], snapshot["gizmos"])):
            apart = (np.linalg.norm(target.translation - gizmo.translation) > 1e-3
                     or np.linalg.norm(pin.log3(gizmo.rotation.T @ target.rotation)) > 1e-2)
            marker = self.target_markers[index]
            marker.visible = bool(apart or snapshot["clutch"])
            marker.position = target.translation
            marker.wxyz = wxyz_of(target.rotation)
            lines = {"main": self.reach_lines[index]}
            if ghost:
                self.ghost_targets[index].position = target.translation
                self.ghost_targets[index].wxyz = wxyz_of(target.rotation)
                lines["ghost"] = self.ghost_reaches[index]
            for which, line in lines.items():
                robot = snapshot["robots"][which]
                limitation = robot["limitations"][index]
                line.points = np.array([[robot["ees"][index].translation, target.translation]])
                color = STATUS_COLORS.get(limitation.status, STATUS_COLORS["failed"])
                if self._line_colors.get((which, index)) != color:
                    line.colors = np.tile(np.array(color, dtype=np.uint8), (1, 2, 1))
                    self._line_colors[(which, index)] = color
                line.visible = limitation.distance > 2e-4
