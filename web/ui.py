"""The viser front end: a thin layer over :class:`web.app.TeleopApp`.

* scene: the robot (:class:`web.robot_view.RobotView`: any URDF, meshes or fallbacks; a
  mobile base moves with its planar root joint), an optional ghost robot drawn beside it
  (``ghost_offset``; zero overlays them), the grid at the robot's base; per end effector an
  input gizmo and, where it differs, the target itself; per robot and EE a line from the
  EE to its target coloured by the step status, and each constraint as its
  ``geometry()`` says (holes as rings on the link axis, planes as translucent squares,
  barriers in red with an arrow to their allowed side, walls on a mobile base as large as
  the base, point locks as spheres at their target), the constraint point as a collar
  around its link, the constraint error as a short vector (drawn x100) when it is not zero;
* panels: a status (rate, lateness, what limits each robot's EEs in words, active
  barriers), then tabs: Teleop (controllers, side by side, clutch, motion scale, the
  active arm's nudges, home), Constraints (each on the arm or link chosen), Settings
  (gain, damping, rate, scenes, recording), Plots (uPlot).

A robot with several end effectors (docs/design.md section 11) gets a gizmo on each: each
drives its own EE's target; the clutch and the motion scale act on all of them; the nudge
buttons and "Gizmo to target" act on the arm chosen as "active arm"; "Home" homes every EE.

Several browsers may connect: they share the targets and one scene (the last drag wins).
A browser that disconnects mid-drag leaves its target where the robot's EE is at that
moment, not where the drag was, so the robot settles where it is. Every action goes
through one coalescing inbox (web/inbox.py), so a flood of events cannot starve the
control loop; the status turns red (a banner and a notification) when the loop achieves
less than 95 % of its rate. Scenes and recordings are plain file names in the folders the
server was started with (web/folders.py).
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import viser
import viser.uplot as uplot

from constraints import ConstraintGeometry
from teleop.controller_specs import default_specs
from teleop.robots import Robot

from .access import require_token
from .app import HISTORY_SECONDS, ControlThread, TeleopApp, default_ghost_offset
from .inbox import Inbox
from .robot_view import RobotView, floor_height

CONTROLLER_CHOICES = default_specs("ui")  # the dropdowns (plus a spec given on the command line)
VIEW_RATE = 30.0  # Hz: robot poses, markers, status
PLOT_RATE = 10.0  # Hz: live plots
STATUS_RATE = 5.0  # Hz: the status text (readable, and light on the browser)
GHOST_PLOTS_FIRST = 0.5  # s: a new ghost is drawn once the plots show it, or after this
ERROR_VECTOR_SCALE = 100.0
MAIN_COLOR = "#d97706"
GHOST_COLOR = "#2563eb"
GHOST_DASH = (6.0, 4.0)  # the ghost's plot lines are dashed: the main one shows where they agree
GHOST_RGBA = (0.45, 0.7, 1.0, 0.8)  # beside the main robot
GHOST_OVERLAY_RGBA = (0.25, 0.5, 0.95, 0.4)  # on it: see-through
#: the EE-target line's colour for each step status
STATUS_COLORS = {"ok": (30, 160, 70), "scaled": (230, 170, 0), "least_squares": (240, 110, 0),
                 "constraint_degraded": (220, 30, 30), "failed": (150, 0, 150)}
NUDGES = {"-x": (-1, 0, 0), "+x": (1, 0, 0), "-y": (0, -1, 0), "+y": (0, 1, 0),
          "-z": (0, 0, -1), "+z": (0, 0, 1)}
BARRIER_ARROW = 0.08  # m
BEHIND_COLOR = "#b91c1c"  # the banner of a control loop falling behind


def _wxyz(rotation: np.ndarray) -> tuple[float, float, float, float]:
    quaternion = pin.Quaternion(rotation)
    return quaternion.w, quaternion.x, quaternion.y, quaternion.z


def _wxyz_from_z(direction: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) of a rotation taking +z to ``direction``."""
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), np.asarray(direction, float))
    return np.array([rotation.w, rotation.x, rotation.y, rotation.z])


def _perpendicular(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _ring(center: np.ndarray, axis: np.ndarray, radius: float = 0.015, n: int = 32) -> np.ndarray:
    """Line segments (n, 2, 3) of a circle around ``axis`` through ``center``."""
    u, v = _perpendicular(np.asarray(axis, dtype=float))
    angles = np.linspace(0.0, 2.0 * np.pi, n + 1)
    points = center + radius * (np.outer(np.cos(angles), u) + np.outer(np.sin(angles), v))
    return np.stack([points[:-1], points[1:]], axis=1)


def _arrow(start: np.ndarray, direction: np.ndarray, length: float) -> np.ndarray:
    """Line segments (5, 2, 3) of an arrow from ``start`` along the unit ``direction``."""
    tip = start + length * direction
    u, v = _perpendicular(direction)
    head = 0.25 * length
    barbs = [tip - head * direction + 0.5 * head * side for side in (u, -u, v, -v)]
    return np.array([[start, tip], *[[tip, barb] for barb in barbs]])


def _geometry_points(geometry) -> np.ndarray:
    """Points (n, 3) on one geometry in its own frame: a mesh's vertices; circles on a
    cylinder or capsule (axis z), points on a sphere; else a 5x5x5 grid filling its
    bounding box (a box...)."""
    kind = type(geometry).__name__
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    circle = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    if kind in ("Cylinder", "Capsule"):
        half = geometry.halfLength + (geometry.radius if kind == "Capsule" else 0.0)
        return np.concatenate([geometry.radius * circle + [0.0, 0.0, z]
                               for z in np.linspace(-half, half, 9)])
    if kind == "Sphere":
        return np.concatenate([geometry.radius * np.sin(polar) * circle
                               + [0.0, 0.0, geometry.radius * np.cos(polar)]
                               for polar in np.linspace(0.0, np.pi, 9)])
    if hasattr(geometry, "vertices"):
        try:
            vertices = np.asarray(geometry.vertices(), dtype=float)
            if vertices.ndim == 2 and vertices.shape[1] == 3 and len(vertices):
                return vertices
        except (AttributeError, RuntimeError, TypeError):
            pass
    try:
        geometry.computeLocalAABB()
        low = np.asarray(geometry.aabb_local.min_, dtype=float)
        high = np.asarray(geometry.aabb_local.max_, dtype=float)
    except (AttributeError, RuntimeError):
        return np.zeros((0, 3))
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        return np.zeros((0, 3))
    grid = np.linspace(0.0, 1.0, 5)
    weights = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    return low + weights * (high - low)


@dataclass(frozen=True)
class LinkProfile:
    """Where a link's geometry (visual and collision) is around an axis through the link
    frame's origin: per point, its coordinate along the axis and its distance from it
    (link frame, m). A ring drawn around the axis at ``s`` must be wider than
    :meth:`radius_at` ``s`` to be seen outside the link's mesh."""

    along: np.ndarray
    radial: np.ndarray

    #: half the slab of the link (m, along the axis) a ring at ``s`` must clear
    SLAB = 0.03

    @classmethod
    def of(cls, robot: Robot, link: str | None, axis=None) -> "LinkProfile":
        """The profile of ``link`` around ``axis`` (default: its instrument axis
        ``robot.link_axes[link]``, else the link frame's z); empty without geometry."""
        empty = cls(np.zeros(0), np.zeros(0))
        model = robot.model
        if link is None or not model.existFrame(link):
            return empty
        frame_id = model.getFrameId(link)
        frame = model.frames[frame_id]
        axis = np.asarray(robot.link_axes.get(link, (0.0, 0.0, 1.0)) if axis is None else axis,
                          dtype=float)
        axis = axis / np.linalg.norm(axis)
        points = []
        for geometry_model in (robot.visual_model, robot.collision_model):
            for geometry_object in getattr(geometry_model, "geometryObjects", ()):
                if geometry_object.parentFrame != frame_id:
                    continue
                in_link = frame.placement.actInv(geometry_object.placement)
                local = _geometry_points(geometry_object.geometry)
                if len(local):
                    points.append(local @ in_link.rotation.T + in_link.translation)
        if not points:
            return empty
        points = np.concatenate(points)
        along = points @ axis
        radial = np.linalg.norm(points - np.outer(along, axis), axis=1)
        return cls(along, radial)

    def radius_at(self, s: float | None = None) -> float:
        """How far the geometry reaches from the axis within :attr:`SLAB` of ``s`` (the
        whole link when ``s`` is None or no geometry is there); 0 without geometry."""
        if not self.radial.size:
            return 0.0
        if s is not None:
            near = np.abs(self.along - s) <= self.SLAB
            if np.any(near):
                return float(self.radial[near].max())
        return float(self.radial.max())


def _link_radius(robot: Robot, link: str | None) -> float:
    """How far ``link``'s geometry reaches from its instrument axis (0 without one)."""
    return LinkProfile.of(robot, link).radius_at()


#: a ring is this much wider than the geometry it goes around (ratio, and m)
RING_MARGIN = (1.1, 0.005)
MIN_RING_RADIUS = 0.015  # m


def _ring_around(radius: float, minimum: float = MIN_RING_RADIUS) -> float:
    """A ring's radius around geometry reaching ``radius`` from the axis: outside it."""
    return max(minimum, RING_MARGIN[0] * radius + RING_MARGIN[1])


def _link_extent(robot: Robot, link: str) -> float:
    """Half the largest horizontal size of ``link``'s visual geometry (0 when it has none)."""
    if not robot.model.existFrame(link):
        return 0.0
    frame_id = robot.model.getFrameId(link)
    extents = []
    for geometry_object in robot.visual_model.geometryObjects:
        if geometry_object.parentFrame != frame_id:
            continue
        try:
            geometry_object.geometry.computeLocalAABB()
            size = np.asarray(geometry_object.geometry.aabb_local.max_) \
                - np.asarray(geometry_object.geometry.aabb_local.min_)
        except (AttributeError, RuntimeError):
            continue
        extents.append(0.5 * float(np.max(size[:2])))
    return max(extents, default=0.0)


#: the square a plane is drawn as: this wide (m), or twice its link's size (a wall beside a
#: mobile base spans the base)
PLANE_SIZE = 0.3


def _plane_size(robot: Robot, link: str) -> float:
    return max(PLANE_SIZE, 4.0 * _link_extent(robot, link))


def _short_names(frames: tuple[str, ...]) -> dict[str, str]:
    """Each EE frame's name for the operator: without the prefix and suffix they share
    (``arm_left_link_tool0``, ``arm_right_link_tool0`` -> ``left``, ``right``)."""
    if len(frames) < 2:
        return {frame: frame for frame in frames}
    words = [frame.split("_") for frame in frames]
    prefix = len(os.path.commonprefix(words))
    suffix = len(os.path.commonprefix([w[::-1] for w in words]))
    names = {frame: "_".join(w[prefix:len(w) - suffix]) for frame, w in zip(frames, words)}
    if len(set(names.values())) < len(frames) or not all(names.values()):
        return {frame: frame for frame in frames}
    return names


# -- plots ---------------------------------------------------------------------------------

#: display units per quantity: (name, size in SI units), largest first
UNITS = {"m": (("m", 1.0), ("mm", 1e-3), ("µm", 1e-6), ("nm", 1e-9)),
         "m/s": (("m/s", 1.0), ("mm/s", 1e-3), ("µm/s", 1e-6), ("nm/s", 1e-9)),
         "us": (("µs", 1.0),),
         "rad/s": (("rad/s", 1.0), ("mrad/s", 1e-3), ("µrad/s", 1e-6), ("nrad/s", 1e-9))}


def display_unit(values: np.ndarray, quantity: str, current: str | None = None) -> tuple[str, float]:
    """The unit that shows ``values`` as readable numbers (the largest with a peak >= 1),
    kept while the peak stays within [0.5, 2000) of ``current`` (no flicker)."""
    units = UNITS[quantity]
    finite = values[np.isfinite(values)]
    peak = float(np.max(np.abs(finite))) if finite.size else 0.0
    sizes = dict(units)
    if current in sizes and 0.5 <= peak / sizes[current] < 2000.0:
        return current, sizes[current]
    for name, size in units:
        if peak >= size:
            return name, size
    return units[-1]


@dataclass(frozen=True)
class PlotSpec:
    key: str  # a Trace column
    title: str
    quantity: str  # a key of UNITS
    ghost_only: bool = False


PLOTS = (PlotSpec("constraint_error", "constraint error", "m"),
         PlotSpec("constraint_velocity", "constraint velocity |C v_c|", "m/s"),
         PlotSpec("ee_error", "EE position error", "m"),
         PlotSpec("step_time", "controller step time", "us"),
         PlotSpec("qd_deviation", "joint-velocity deviation |qd_ghost - qd_main|", "rad/s",
                  ghost_only=True))

#: x: the last 10 s, "now" at 0. A fixed range: an auto-ranged x axis of a plot updated
#: while its tab is hidden keeps a stale range in viser's client (the lines fall outside)
X_RANGE = (-HISTORY_SECONDS, 0.0)
#: y from 0 (the measures are norms), at least up to 1 display unit: an all-zero trace
#: reads "0 ... 1 nm", not uPlot's default 0-100
Y_RANGE = {"min": {"pad": 0.0, "soft": 0.0, "mode": 1}, "max": {"pad": 0.1, "soft": 1.0, "mode": 1}}


def plot_series(snapshot: dict, spec: PlotSpec) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Time and the series of one plot, all finite and of one length: with a ghost, the
    samples since it joined (both robots measured at the same ticks)."""
    robots = snapshot["robots"]
    traces = {which: robot["trace"] for which, robot in robots.items()}
    shown = ["ghost"] if spec.ghost_only else list(traces)
    if spec.ghost_only and "ghost" not in traces:
        return np.zeros(0), {}
    n = min(traces[which]["t"].size for which in traces)
    t = traces["main"]["t"][-n:] if n else np.zeros(0)
    series = {which: traces[which][spec.key][-n:] for which in shown} if n else {}
    return t, series


class TeleopUI:
    """Builds the scene and panels on ``server`` and keeps them in sync with ``app``.

    ``notes`` are what the caller wants the operator told on connecting (e.g. the
    warnings of loading the robot), with the meshes' own fallbacks.
    """

    def __init__(self, server: viser.ViserServer, app: TeleopApp, control: ControlThread,
                 notes: list[str] | tuple[str, ...] = ()) -> None:
        self.server = server
        self.app = app
        self.control = control
        self._stop = threading.Event()
        #: every operator action goes through it (web/inbox.py), never straight to the app
        self.inbox = Inbox(self._failed)
        self._gone: set[int] = set()  # browsers that disconnected mid-drag
        self._behind = ""  # the warning shown while the control loop falls behind
        self._markers: dict[str, dict] = {}  # main robot: entry id -> handles
        self._ghost_markers: dict[str, dict] = {}
        self._views: dict[str, RobotView] = {}
        self._ghost_root = None
        self._ghost_style: tuple | None = None
        self._syncing = False  # widgets being set from the app: their callbacks do nothing
        self._plots: dict[str, object] = {}
        self._plot_keys: dict[str, tuple] = {}
        self._line_colors: dict[tuple[str, int], tuple] = {}  # (robot, EE) -> its line colour
        self._plotted: set[str] = set()  # the robots the plots show
        self._ghost_seen: float | None = None  # when the view first saw the ghost
        self._saved_offset = app.ghost_offset.copy()
        robot = app.robot
        #: where each link's geometry is around its axis: rings and collars go outside it
        self.profiles = {link: LinkProfile.of(robot, link) for link in app.plane_links}
        self.plane_sizes = {link: _plane_size(robot, link) for link in app.plane_links}
        self.ee_names = _short_names(robot.ee_frames)  # what the operator reads per EE
        self.floor = floor_height(app.robot)
        self.notes = list(notes)
        self._build_scene()
        self.notes += self._views["main"].problems
        self._build_panels()
        server.on_client_connect(self._greet)
        self._thread = threading.Thread(target=self._view_loop, name="view", daemon=True)

    @property
    def _visualisers(self) -> dict[str, RobotView]:
        """The robots' views by name ("main", "ghost")."""
        return self._views

    # -- scene ---------------------------------------------------------------------------

    def _build_scene(self) -> None:
        scene = self.server.scene
        self.grid = scene.add_grid("/grid", width=4.0, height=4.0, cell_size=0.1,
                                   section_size=0.5, position=(0.0, 0.0, self.floor))
        self._views["main"] = RobotView(self.app.robot, self.server, "/main")
        # per EE: its gizmo, its target (drawn where it is apart from the gizmo), the line
        # from the EE to the target; the first EE's keep the single-EE names
        self.target_gizmos, self.target_markers, self.reach_lines = [], [], []
        for index, target in enumerate(self.app.targets):
            suffix = "" if index == 0 else f"_{index}"
            gizmo = scene.add_transform_controls(
                f"/gizmo{suffix}", scale=0.12, position=target.translation,
                wxyz=_wxyz(target.rotation))
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
        # ghost to the right of the main robot
        side = default_ghost_offset(self.app.robot)
        side /= np.linalg.norm(side)
        front = np.cross(side, [0.0, 0.0, 1.0])
        look_at = np.mean([target.translation for target in self.app.targets], axis=0)
        distance = 1.0
        if "ghost" in self.app.loops:
            look_at += 0.5 * self.app.ghost_offset
            distance += 0.8 * float(np.linalg.norm(self.app.ghost_offset))
        direction = 0.8 * front - 0.3 * side + np.array([0.0, 0.0, 0.5])
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

    def _ghost_rgba(self) -> tuple[float, float, float, float]:
        overlay = float(np.linalg.norm(self.app.ghost_offset)) < 1e-9
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
        self._ghost_markers.clear()

    # -- panels --------------------------------------------------------------------------

    def _guarded(self, event, action, key: object = None, throttled: bool = False) -> None:
        """Post an operator action to the inbox (:mod:`web.inbox`: applied in order on its
        own thread; with a ``key``, the latest wins; ``throttled``, at most 10 a second);
        an impossible one becomes a notification, not a traceback."""
        if self._syncing:
            return
        self.inbox.post(action, key=key, context=event, throttled=throttled)

    def _failed(self, event, error: Exception) -> None:
        """An action from ``event`` could not be done: tell its browser why."""
        if isinstance(error, ValueError):
            self.notify(event, "Not possible", str(error))
        else:
            self.notify(event, "Error", f"{type(error).__name__}: {error}")

    def notify(self, event, title: str, body: str, color: str = "red") -> None:
        clients = [event.client] if event is not None and event.client is not None else \
            list(self.server.get_clients().values())
        for client in clients:
            client.add_notification(title, body, auto_close_seconds=8.0, color=color)

    def _greet(self, client: viser.ClientHandle) -> None:
        """Tell a new browser what could not be loaded as asked."""
        if self.notes:
            client.add_notification("Robot loaded with fallbacks", "\n".join(self.notes),
                                    auto_close_seconds=20.0, color="yellow")

    def _build_panels(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Status"):
            self.banner = gui.add_html("", visible=False)  # the control loop falling behind
            self.status = gui.add_markdown("starting...")
        self.tabs = gui.add_tab_group()
        with self.tabs.add_tab("Teleop"):
            self._build_teleop_panel()
        with self.tabs.add_tab("Constraints"):
            self._build_constraint_panel()
        with self.tabs.add_tab("Settings"):
            self._build_settings_panel()
        self._plot_tab = self.tabs.add_tab("Plots")
        with self._plot_tab:
            self.plot_note = gui.add_markdown("the last 10 s, measured at 50 Hz; with a ghost, "
                                              "since it joined")
        if self.notes:
            with self.tabs.add_tab("Robot"):
                gui.add_markdown("**Loaded with fallbacks:**\n\n" +
                                 "\n".join(f"* {note}" for note in self.notes))

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
        self.home_button = gui.add_button("Home", hint="every target to its home pose; the "
                                          "constraints stay")

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
        self.nudge_buttons.on_click(lambda event: self._guarded(event, lambda: app.nudge_target(
            self.nudge_step.value * np.asarray(NUDGES[self.nudge_buttons.value], dtype=float),
            self._active_ee())))
        self.gizmo_button.on_click(lambda event: self._guarded(event, self._gizmo_to_target))
        self.home_button.on_click(lambda event: self._guarded(event, self._home))

    def _build_constraint_panel(self) -> None:
        gui, app = self.server.gui, self.app
        arms = app.robot.constrained_links or ("(none)",)
        self.constraint_arm = gui.add_dropdown(
            "arm", arms, initial_value=arms[0], visible=len(arms) > 1,
            hint="the constrained link (one per arm) a hole or point lock goes on")
        self.hole_distance = gui.add_number("hole at (m)", 0.08, step=0.005,
                                            hint="distance along the constrained link")
        self.add_hole_button = gui.add_button("Add hole")
        links = app.plane_links or ("(none)",)
        self.plane_link = gui.add_dropdown(
            "plane on link", links, initial_value=links[0],
            visible=len(app.robot.ee_frames) > 1 or app.robot.root_joint != "fixed",
            hint="the link a plane or barrier holds: an arm's constrained link, or any "
                 "other (a mobile base: a wall)")
        self.plane_distance = gui.add_number("plane point at (m)", 0.08, step=0.005,
                                             hint="distance along the constrained link")
        self.plane_point = gui.add_vector3(
            "plane point on link (m)", (0.0, 0.0, 0.0), step=0.05, visible=False,
            hint="in the link's own coordinates (a link without an instrument axis)")
        self.plane_normal = gui.add_vector3("plane normal (world)", (0.0, 1.0, 0.0), step=0.1,
                                            hint="in world coordinates; a barrier keeps the "
                                                 "point on the side the normal points to")
        self.barrier_offset = gui.add_number("barrier offset (m)", 0.01, min=0.0, step=0.005)
        self.add_plane_button = gui.add_button("Add plane")
        self.add_barrier_button = gui.add_button("Add barrier")
        self.lock_distance = gui.add_number("point lock at (m)", 0.08, step=0.005,
                                            hint="distance along the constrained link")
        self.add_lock_button = gui.add_button("Add point lock")
        self.constraint_menu = gui.add_dropdown("placed", ("(none)",))
        self.remove_button = gui.add_button("Remove")
        self.clear_button = gui.add_button("Clear constraints")

        self.add_hole_button.on_click(lambda event: self._guarded(
            event, lambda: app.add_hole(self.hole_distance.value, self._arm_link())))
        self.plane_link.on_update(lambda event: self._plane_link_changed())
        self.add_plane_button.on_click(lambda event: self._guarded(
            event, lambda: self._add_plane(barrier=False)))
        self.add_barrier_button.on_click(lambda event: self._guarded(
            event, lambda: self._add_plane(barrier=True)))
        self.add_lock_button.on_click(lambda event: self._guarded(
            event, lambda: app.add_point_lock(self.lock_distance.value, self._arm_link())))
        self.remove_button.on_click(lambda event: self._guarded(
            event, lambda: app.remove_constraint(self.constraint_menu.value)))
        self.clear_button.on_click(lambda event: self._guarded(event, app.clear_constraints))

    def _arm_link(self) -> str | None:
        """The constrained link chosen for a hole or point lock (None: the robot has none)."""
        links = self.app.robot.constrained_links
        return self.constraint_arm.value if self.constraint_arm.value in links else None

    def _plane_link_changed(self) -> None:
        """A link with an instrument axis takes a distance along it, any other a point."""
        on_axis = self.plane_link.value in self.app.robot.link_axes
        self.plane_distance.visible = on_axis
        self.plane_point.visible = not on_axis

    def _add_plane(self, barrier: bool) -> str:
        link = self.plane_link.value if self.plane_link.value in self.app.plane_links else None
        if link is None or link in self.app.robot.link_axes:
            return self.app.add_plane(self.plane_distance.value, self.plane_normal.value,
                                      barrier=barrier, offset=self.barrier_offset.value,
                                      link=link)
        return self.app.add_plane(None, self.plane_normal.value, barrier=barrier,
                                  offset=self.barrier_offset.value, link=link,
                                  link_point=self.plane_point.value)

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

    # -- actions that also update widgets ---------------------------------------------------

    def _active_ee(self) -> int:
        """The index (in ``robot.ee_frames``) of the arm chosen as active."""
        return list(self.ee_names.values()).index(self.active_arm.value)

    def _move_gizmo_handle(self, pose: pin.SE3, ee: int = 0) -> None:
        self.target_gizmos[ee].position = pose.translation
        self.target_gizmos[ee].wxyz = _wxyz(pose.rotation)

    def _move_gizmo_handles(self) -> None:
        """Every gizmo handle where the app's gizmo is."""
        for index, hand in enumerate(self.app.inputs):
            self._move_gizmo_handle(hand.gizmo, index)

    def _home(self) -> None:
        self.app.home()
        self._move_gizmo_handles()

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
        self._move_gizmo_handles()
        self.scene_status.content = f"loaded `{self.app.scenes.name_of(name)}`"

    def _sync(self, action) -> None:
        """Set widgets from the app without their callbacks acting."""
        self._syncing = True
        try:
            action()
        finally:
            self._syncing = False

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
        self.rate_number.value = app.config.rate

    def _toggle_recording(self) -> None:
        if self.app.recorder is None:
            path = self.app.start_recording()
            self.record_button.label = "Stop recording"
            self.record_status.content = f"recording to `{path.name}`"
        else:
            path = self.app.stop_recording()
            self.record_button.label = "Start recording"
            self.record_status.content = f"wrote `{path}` (replay: `teleop replay {path}`)"

    # -- the view thread -------------------------------------------------------------------

    def start(self) -> None:
        self.inbox.start()
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self.inbox.stop()
        self._thread.join(2.0)

    def _view_loop(self) -> None:
        next_plot = next_status = 0.0
        while not self._stop.is_set():
            start = time.perf_counter()
            try:
                plot = start >= next_plot
                status = start >= next_status
                snapshot = self.app.snapshot(history=plot)
                with self.server.atomic():
                    self._draw(snapshot, status=status)
                if status:
                    next_status = start + 1.0 / STATUS_RATE
                if plot:
                    self._plot(snapshot)
                    next_plot = start + 1.0 / PLOT_RATE
            except Exception as error:  # the view must never take the control loop down
                self.status.content = f"view error: {type(error).__name__}: {error}"
            time.sleep(max(0.0, 1.0 / VIEW_RATE - (time.perf_counter() - start)))

    def _draw(self, snapshot: dict, status: bool = True) -> None:
        robots = snapshot["robots"]
        if "ghost" in robots:
            if "ghost" in self._views and self._ghost_style != self._ghost_rgba():
                self._remove_ghost()  # overlay <-> beside: see-through or not
            if "ghost" not in self._views and self._ghost_due():
                self._add_ghost(snapshot["ghost_offset"])
            if self._ghost_root is not None:
                self._ghost_root.position = snapshot["ghost_offset"]
        else:
            self._ghost_seen = None
            if "ghost" in self._views:
                self._remove_ghost()
        for which, view in self._views.items():
            view.display(robots[which]["q"])
        self._draw_target(snapshot)
        ghost = snapshot["robots"].get("ghost") if "ghost" in self._views else None
        self._draw_constraints(snapshot["constraints"],
                               None if ghost is None else ghost["constraints"])
        if status:
            self._draw_status(snapshot)

    def _ghost_due(self) -> bool:
        """Whether to draw a ghost that just joined: once the plots show it (or after
        GHOST_PLOTS_FIRST s). A browser compiles the shaders of new meshes on their first
        frame, which holds a software-rendered page for seconds: the plots go first."""
        now = time.perf_counter()
        if self._ghost_seen is None:
            self._ghost_seen = now
        return ("ghost" in self._plotted or now - self._ghost_seen > GHOST_PLOTS_FIRST)

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
            marker.wxyz = _wxyz(target.rotation)
            lines = {"main": self.reach_lines[index]}
            if ghost:
                self.ghost_targets[index].position = target.translation
                self.ghost_targets[index].wxyz = _wxyz(target.rotation)
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

    def _draw_constraints(self, entries: list[dict], ghost: dict | None = None) -> None:
        """The main robot's constraint markers (``snapshot["constraints"]``) and, given the
        ghost's drawings (``snapshot["robots"]["ghost"]["constraints"]``), the ghost's."""
        goals = {e["id"]: e["goal"] for e in entries}
        main = {e["id"]: e for e in entries}
        for drawn, markers_of, prefix in ((main, self._markers, "/constraints"),
                                          (ghost, self._ghost_markers, "/ghost/constraints")):
            if drawn is None:
                continue
            for entry_id in list(markers_of):
                if entry_id not in drawn:
                    for handle in markers_of.pop(entry_id).values():
                        handle.remove()
            for entry_id, drawing in drawn.items():
                markers = markers_of.get(entry_id)
                if markers is None:
                    markers = markers_of[entry_id] = self._create_markers(
                        f"{prefix}/{entry_id}", entry_id, drawing, goals[entry_id],
                        gizmo=markers_of is self._markers)
                self._update_markers(markers, drawing)
        options = tuple(e["id"] for e in entries) or ("(none)",)
        if tuple(self.constraint_menu.options) != options:
            self.constraint_menu.options = options

    def _add_shape(self, name: str, drawing: dict):
        """The scene node of a constraint's geometry, drawn as its ``shape`` says (a ring
        around its link, a plane as wide as it)."""
        scene = self.server.scene
        geometry, link = drawing["geometry"], drawing["link"]
        if geometry.shape == "ring":
            ring = _ring(geometry.anchor, geometry.axis, self.ring_radius_at(drawing))
            return scene.add_line_segments(f"{name}/ring", ring, geometry.color, thickness=0.004)
        if geometry.shape == "plane":
            size = self.plane_sizes.get(link, PLANE_SIZE)
            return scene.add_box(f"{name}/plane", geometry.color, (size, size, 0.001),
                                 opacity=0.3, side="double", wxyz=_wxyz_from_z(geometry.axis),
                                 position=geometry.anchor)
        return scene.add_icosphere(f"{name}/anchor", 0.012, geometry.color, opacity=0.5,
                                   position=geometry.anchor)

    def _along(self, link: str, placement: pin.SE3, point: np.ndarray) -> float:
        """Where the world ``point`` is along ``link``'s axis (link frame, m)."""
        axis = np.asarray(self.app.robot.link_axes.get(link, (0.0, 0.0, 1.0)), dtype=float)
        return float(placement.actInv(np.asarray(point, dtype=float)) @ axis
                     / np.linalg.norm(axis))

    def ring_radius_at(self, drawing: dict) -> float:
        """Radius of the ring of a hole drawn as ``drawing`` (a snapshot's constraint):
        outside the geometry of its link where the ring is (:class:`LinkProfile`)."""
        link, geometry = drawing["link"], drawing["geometry"]
        profile = self.profiles.get(link)
        if profile is None:
            return MIN_RING_RADIUS
        return _ring_around(profile.radius_at(
            self._along(link, drawing["link_placement"], geometry.anchor)))

    def collar_radius_at(self, drawing: dict) -> float:
        """Radius of the collar around the link at the constrained point (0: none)."""
        link, geometry = drawing["link"], drawing["geometry"]
        profile = self.profiles.get(link)
        if profile is None or not profile.radial.size:
            return 0.0
        radius = profile.radius_at(self._along(link, drawing["link_placement"], geometry.point))
        return _ring_around(radius, minimum=0.0) - 0.001

    def _point_marker(self, drawing: dict) -> np.ndarray | None:
        """The collar around the link at the constrained point (None: draw a sphere)."""
        axis, radius = drawing["link_axis"], self.collar_radius_at(drawing)
        if axis is None or radius <= 0.004:
            return None
        return _ring(drawing["geometry"].point, axis, radius, n=24)

    def _create_markers(self, name: str, entry_id: str, drawing: dict, goal: np.ndarray,
                        gizmo: bool) -> dict:
        scene = self.server.scene
        geometry: ConstraintGeometry = drawing["geometry"]
        markers = {"shape": self._add_shape(name, drawing)}
        collar = self._point_marker(drawing)
        if collar is not None:  # outside the link cylinder: visible, unlike a point inside
            markers["point"] = scene.add_line_segments(f"{name}/point", collar, (20, 20, 20),
                                                       thickness=0.004)
        else:
            markers["point"] = scene.add_icosphere(f"{name}/point", 0.008, (20, 20, 20),
                                                   position=geometry.point)
        markers["error"] = scene.add_line_segments(f"{name}/error", np.zeros((1, 2, 3)),
                                                   (255, 0, 255), thickness=0.003)
        if geometry.kind == "barrier":  # the allowed side
            markers["arrow"] = scene.add_line_segments(
                f"{name}/arrow", _arrow(geometry.anchor, geometry.axis, BARRIER_ARROW),
                geometry.color, thickness=0.004)
        if gizmo:  # drawn over the links (depth_test off): never hidden inside one
            handle = scene.add_transform_controls(f"{name}/gizmo", scale=0.07, position=goal,
                                                  disable_rotations=True, depth_test=False)

            @handle.on_update
            def _(event) -> None:
                position = np.array(handle.position)
                self._guarded(event, lambda: self.app.move_constraint(entry_id, position),
                              key=("constraint", entry_id))

            markers["gizmo"] = handle
        return markers

    def _update_markers(self, markers: dict, drawing: dict) -> None:
        geometry: ConstraintGeometry = drawing["geometry"]
        if geometry.shape == "ring":  # around the link axis, which turns with the link
            markers["shape"].points = _ring(geometry.anchor, geometry.axis,
                                            self.ring_radius_at(drawing))
        else:
            markers["shape"].position = geometry.anchor
        collar = self._point_marker(drawing)
        if collar is not None:
            markers["point"].points = collar
        else:
            markers["point"].position = geometry.point
        # from the point towards where it should be (the error points the other way)
        vector = -ERROR_VECTOR_SCALE * geometry.error
        markers["error"].points = np.array([[geometry.point, geometry.point + vector]])
        markers["error"].visible = float(np.linalg.norm(geometry.error)) > 1e-6
        if "arrow" in markers:
            markers["arrow"].points = _arrow(geometry.anchor, geometry.axis, BARRIER_ARROW)

    def _warn_behind(self) -> None:
        """A red banner above the status (and a notification when it starts) while the
        control loop achieves less than 95 % of its rate (``ControlThread.behind``)."""
        behind = self.control.behind()
        if bool(behind) != bool(self._behind):
            if behind:
                self.notify(None, "Control loop behind", behind, color="red")
            self.banner.visible = bool(behind)
        if behind and behind != self._behind:
            self.banner.content = (f'<div style="background:{BEHIND_COLOR};color:white;'
                                   f'padding:6px 8px;border-radius:4px;font-weight:600">'
                                   f'{behind}</div>')
        self._behind = behind

    def _draw_status(self, snapshot: dict) -> None:
        self._warn_behind()
        timing = self.control.timing()
        control = (f"**control{' BEHIND' if self._behind else ''}** "
                   f"{timing.achieved_rate:.0f} Hz achieved (target "
                   f"{snapshot['config'].rate:.0f} Hz), lateness p99 "
                   f"{timing.lateness_p99_ms:.2f} ms, tick {timing.tick_p50_us:.0f} us "
                   f"({timing.overhead_p50_us:.0f} us beyond the controllers), "
                   f"{timing.deadline_misses} deadline misses")
        lines = [control]
        if self.control.error:
            lines.append(f"**control error** {self.control.error}")
        names = [self.ee_names[frame] for frame in snapshot["ee_frames"]]
        for which, robot in snapshot["robots"].items():
            record, limitation = robot["record"], robot["limitation"]
            if len(names) == 1:
                words = f"**{which}** `{robot['spec']}` **{limitation.status}**: {limitation.words}"
                if record is not None:
                    words += (f" (constraint {max(record.constraint_error, record.barrier_penetration):.1e} m, "
                              f"EE {1e3 * limitation.distance:.2f} mm from the target, "
                              f"step {record.step_time_us:.0f} us)")
            else:  # one status per robot, what keeps each EE from its target
                words = f"**{which}** `{robot['spec']}` **{limitation.status}**: " + "; ".join(
                    f"*{name}* {each.words} ({1e3 * each.distance:.2f} mm from its target)"
                    for name, each in zip(names, robot["limitations"]))
                if record is not None:
                    words += (f" (constraint {max(record.constraint_error, record.barrier_penetration):.1e} m, "
                              f"step {record.step_time_us:.0f} us)")
            if robot["active_barriers"]:
                words += f"; active barriers: {', '.join(robot['active_barriers'])}"
            lines.append(words)
        console = [f"motion scale {snapshot['motion_scale']:g}"]
        if snapshot["clutch"]:
            console.insert(0, "**clutch engaged**: the gizmo moves alone" if len(names) == 1
                           else "**clutch engaged**: the gizmos move alone")
        lines.append(", ".join(console))
        self.status.content = "  \n".join(lines)
        label = "Release clutch" if snapshot["clutch"] else "Clutch"
        if self.clutch_button.label != label:
            self.clutch_button.label = label

    def _plot(self, snapshot: dict) -> None:
        robots = snapshot["robots"]
        shown: set[str] = set()
        for spec in PLOTS:
            t, series = plot_series(snapshot, spec)
            if t.size < 2:
                if spec.ghost_only and spec.key in self._plots and "ghost" not in robots:
                    self._plots.pop(spec.key).remove()
                    self._plot_keys.pop(spec.key, None)
                continue
            values = np.concatenate(list(series.values()))
            current = self._plot_keys.get(spec.key, (None,))[0]
            unit, size = display_unit(values, spec.quantity, current)
            labels = tuple(f"{which} ({robots[which]['spec']})" for which in series)
            key = (unit, labels)
            data = (t - snapshot["robots"]["main"]["t"],  # seconds before now: a fixed x axis
                    *[column / size for column in series.values()])
            if self._plot_keys.get(spec.key) != key:
                self._replace_plot(spec, unit, series, labels, data)
                self._plot_keys[spec.key] = key
            else:
                self._plots[spec.key].data = data
            shown.update(series)
        self._plotted = shown

    def _replace_plot(self, spec: PlotSpec, unit: str, series: dict, labels: tuple,
                      data: tuple) -> None:
        """A new uPlot for a new unit or set of series, where the old one was."""
        old = self._plots.pop(spec.key, None)
        order = old.order if old is not None else None
        if old is not None:
            old.remove()
        colors = {"main": MAIN_COLOR, "ghost": GHOST_COLOR}
        with self._plot_tab:
            self._plots[spec.key] = self.server.gui.add_uplot(
                data=data,
                series=(uplot.Series(label="t - now (s)"),
                        *[uplot.Series(label=label, stroke=colors[which], width=1.5,
                                       **({} if which == "main" else {"dash": GHOST_DASH}))
                          for which, label in zip(series, labels)]),
                title=f"{spec.title} ({unit})", aspect=2.2, order=order,
                scales={"x": uplot.Scale(time=False, auto=False, range=X_RANGE),
                        "y": uplot.Scale(auto=True, range=Y_RANGE)})


def run_server(robot: Robot, host: str = "127.0.0.1", port: int = 8080,
               controller: str = "cjm", ghost: str | None = None, rate: float = 1000.0,
               record_dir: str | Path = "sessions", scene: dict | None = None,
               notes: list[str] | tuple[str, ...] = (), scene_dir: str | Path = "scenes",
               token: str | None = None
               ) -> tuple[viser.ViserServer, TeleopApp, ControlThread, TeleopUI]:
    """Start the app: server bound to ``host`` (loopback by default), control and view
    threads. ``scene`` (a scene dict for this robot) is applied before anything runs.
    The page reads and writes files in ``scene_dir`` and ``record_dir`` only; with a
    ``token``, a page that does not present it gets nothing (:mod:`web.access`)."""
    app = TeleopApp(robot, controller=controller, ghost=ghost, rate=rate, record_dir=record_dir,
                    scene_dir=scene_dir)
    if scene is not None:
        app.apply_scene(scene)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    if token is not None:
        require_token(server, token)
        # a page that connected before the check was in place (nothing is served yet)
        # reconnects, and is checked
        server._websock_server.disconnect_all_clients()
    control = ControlThread(app)
    ui = TeleopUI(server, app, control, notes=notes)
    control.start()
    ui.start()
    return server, app, control, ui

