"""The 3D scene: the robot (and its ghost), the grid, per end effector an input gizmo, its
target and the line from the EE to it in the step status's colour; a browser lost
mid-drag holds its target where the robot is (docs/design.md section 5.3)."""

from __future__ import annotations

import time
from collections.abc import Callable, Collection
from typing import Any

import numpy as np
import pinocchio as pin
import viser

from ..app import TeleopApp, default_ghost_offset
from ..robot_view import RobotView
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
    """The robots, gizmos and targets of :class:`web.ui.TeleopUI`, a component owning
    their nodes: :attr:`views` (the robots' views by name, "main" and, while drawn,
    "ghost"), per EE :attr:`target_gizmos`, :attr:`target_markers`, :attr:`reach_lines`
    (the first EE's also as :attr:`target_gizmo`, :attr:`target_marker`,
    :attr:`reach_line`) and the ghost's root, targets and lines.

    Parameters
    ----------
    server : the viser server.
    app : the session (its robot, targets, gizmos and ghost).
    guarded : posts an operator action (:meth:`web.ui.TeleopUI._guarded`), the hold of a
        browser lost mid-drag among them.
    floor : the grid's height (m).
    ghost_removed : called when the ghost's nodes went (with its root: what is drawn under
        it forgets them).
    """

    def __init__(self, server: viser.ViserServer, app: TeleopApp,
                 guarded: Callable[..., None], floor: float,
                 ghost_removed: Callable[[], None]) -> None:
        self.server = server
        self.app = app
        self._guarded = guarded
        self._ghost_removed = ghost_removed
        self._gone: set[int] = set()  # browsers that disconnected mid-drag
        self.views: dict[str, RobotView] = {"main": RobotView(app.robot, server, "/main")}
        self.ghost_root: viser.FrameHandle | None = None
        self.ghost_style: tuple[float, float, float, float] | None = None
        self.ghost_seen: float | None = None  # when the view first saw the ghost
        self.ghost_targets: list[viser.FrameHandle] = []
        self.ghost_reaches: list[viser.LineSegmentsHandle] = []
        #: (robot, EE) -> its EE-target line's colour
        self._line_colors: dict[tuple[str, int], tuple[int, int, int]] = {}
        scene = server.scene
        self.grid = scene.add_grid("/grid", width=4.0, height=4.0, cell_size=0.1,
                                   section_size=0.5, position=(0.0, 0.0, floor))
        # per EE: its gizmo, its target (drawn where it is apart from the gizmo), the line
        # from the EE to the target; the first EE's keep the single-EE names
        self.target_gizmos: list[viser.TransformControlsHandle] = []
        self.target_markers: list[viser.FrameHandle] = []
        self.reach_lines: list[viser.LineSegmentsHandle] = []
        size = GIZMO_SCALE if len(app.console.targets) == 1 else GIZMO_SCALE_SEVERAL
        for index, target in enumerate(app.console.targets):
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
        side = default_ghost_offset(app.robot)
        side /= np.linalg.norm(side)
        front = np.cross([0.0, 0.0, 1.0], side)
        look_at = np.mean([target.translation for target in app.console.targets], axis=0)
        distance = 1.0
        if "ghost" in app.robots.loops:
            look_at += 0.5 * app.robots.ghost_offset
            distance += 0.8 * float(np.linalg.norm(app.robots.ghost_offset))
        direction = 0.8 * front + 0.3 * side + np.array([0.0, 0.0, 0.5])
        server.initial_camera.position = look_at + distance * direction / np.linalg.norm(direction)
        server.initial_camera.look_at = look_at

    def _gizmo_moved(self, gizmo: viser.TransformControlsHandle,
                     index: int) -> Callable[[viser.TransformControlsEvent], None]:
        """The callback of EE ``index``'s gizmo: the app moves that EE's target, the
        latest pose winning. A drag that viser ends because its browser went away holds
        the target where the robot is (:meth:`web.app.console.Console.hold_where_the_robot_is`)."""
        def moved(event: viser.TransformControlsEvent) -> None:
            client = event.client_id
            if client is not None and client not in self.server.get_clients():
                if event.phase == "end":
                    self._lost_mid_drag(client, index)
                return
            position, wxyz = np.array(gizmo.position), np.array(gizmo.wxyz)
            self._guarded(event, lambda: None if client in self._gone else
                          self.app.console.move_gizmo(position, wxyz, index), key=("gizmo", index))
        return moved

    def _lost_mid_drag(self, client: int, index: int) -> None:
        """Browser ``client`` disconnected while dragging EE ``index``'s gizmo: its moves
        still pending are dropped, the target held where the EE is, the handle put there
        for the other browsers."""
        self._gone.add(client)

        def hold() -> None:
            self.app.console.hold_where_the_robot_is(index)
            self.move_gizmo(self.app.console.inputs[index].gizmo, index)

        self._guarded(None, hold, key=("hold", index))

    def move_gizmo(self, pose: pin.SE3, ee: int = 0) -> None:
        """EE ``ee``'s gizmo handle put at ``pose`` (for every browser)."""
        self.target_gizmos[ee].position = pose.translation
        self.target_gizmos[ee].wxyz = wxyz_of(pose.rotation)

    def move_gizmos(self) -> None:
        """Every gizmo handle where the app's gizmo is."""
        for index, hand in enumerate(self.app.console.inputs):
            self.move_gizmo(hand.gizmo, index)

    def _ghost_rgba(self) -> tuple[float, float, float, float]:
        overlay = float(np.linalg.norm(self.app.robots.ghost_offset)) < 1e-9
        return GHOST_OVERLAY_RGBA if overlay else GHOST_RGBA

    def _add_ghost(self, offset: np.ndarray) -> None:
        scene = self.server.scene
        self.ghost_root = scene.add_frame("/ghost", show_axes=False, position=offset)
        rgba = self._ghost_rgba()
        self.views["ghost"] = RobotView(self.app.robot, self.server, "/ghost/robot", color=rgba)
        self.ghost_style = rgba
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
        if self.ghost_root is not None:
            self.ghost_root.remove()  # and every node under /ghost
        self.ghost_root = None
        self.views.pop("ghost", None)
        self._ghost_removed()

    def _ghost_due(self, plotted: Collection[str]) -> bool:
        """Whether to draw a ghost that just joined: once the plots show it (or after
        GHOST_PLOTS_FIRST s). A browser compiles the shaders of new meshes on their first
        frame, which holds a software-rendered page for seconds: the plots go first."""
        now = time.perf_counter()
        if self.ghost_seen is None:
            self.ghost_seen = now
        return "ghost" in plotted or now - self.ghost_seen > GHOST_PLOTS_FIRST

    def draw(self, snapshot: dict[str, Any], plotted: Collection[str]) -> None:
        """The robots of ``snapshot`` (a ghost drawn once due, ``plotted`` naming the robots
        the plots show; redrawn when it goes from overlaid to beside or back), the targets
        and the EE-target lines."""
        robots = snapshot["robots"]
        if "ghost" in robots:
            if "ghost" in self.views and self.ghost_style != self._ghost_rgba():
                self._remove_ghost()  # overlay <-> beside: see-through or not
            if "ghost" not in self.views and self._ghost_due(plotted):
                self._add_ghost(snapshot["ghost_offset"])
            if self.ghost_root is not None:
                self.ghost_root.position = snapshot["ghost_offset"]
        else:
            self.ghost_seen = None
            if "ghost" in self.views:
                self._remove_ghost()
        for which, view in self.views.items():
            view.display(robots[which]["q"])
        self._draw_target(snapshot)

    def _draw_target(self, snapshot: dict[str, Any]) -> None:
        """Per EE: its target (where apart from its gizmo, or clutched) and, per robot, the
        line from the EE to it in the step status's colour."""
        ghost = "ghost" in self.views
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
