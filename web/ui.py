"""The viser front end: a thin layer over :class:`web.app.TeleopApp`.

* scene: the robot (Pinocchio's viser visualiser), an optional translucent ghost, a
  transform gizmo for the EE target, and each constraint as its ``geometry()`` says
  (holes as rings on the link axis, planes as translucent squares, barriers in red,
  point locks as spheres at their target), the constraint point on the link, and the
  constraint error as a short vector (drawn x100) when it is not zero;
* panels: controllers, side-by-side, constraints, drift gain / damping / rate, home,
  recording, status (achieved control rate, deadline misses), live plots (uPlot).

Several browsers may connect: they share one target and one scene (the last drag wins).
A browser that disconnects mid-drag leaves the target where it last was, so the robot
converges there and holds still.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import viser
import viser.uplot as uplot
from pinocchio.visualize import ViserVisualizer

from constraints import ConstraintGeometry
from teleop.controller_specs import default_specs
from teleop.robots import Robot

from .app import ControlThread, TeleopApp

CONTROLLER_CHOICES = default_specs("ui")  # the dropdowns (plus a spec given on the command line)
VIEW_RATE = 30.0  # Hz: robot poses, markers, status
PLOT_RATE = 10.0  # Hz: live plots
ERROR_VECTOR_SCALE = 100.0


def _wxyz_from_z(direction: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) of a rotation taking +z to ``direction``."""
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), np.asarray(direction, float))
    return np.array([rotation.w, rotation.x, rotation.y, rotation.z])


def _ring(center: np.ndarray, axis: np.ndarray, radius: float = 0.015, n: int = 32) -> np.ndarray:
    """Line segments (n, 2, 3) of a circle around ``axis`` through ``center``."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    angles = np.linspace(0.0, 2.0 * np.pi, n + 1)
    points = center + radius * (np.outer(np.cos(angles), u) + np.outer(np.sin(angles), v))
    return np.stack([points[:-1], points[1:]], axis=1)


def _ring_radius(robot: Robot, minimum: float = 0.015) -> float:
    """Radius of the hole rings: just outside the constrained link's cylinders (drawn inside them,
    a ring would be hidden by the link it surrounds)."""
    frame_id = robot.model.getFrameId(robot.constrained_link)
    radii = [g.geometry.radius for g in robot.visual_model.geometryObjects
             if g.parentFrame == frame_id and type(g.geometry).__name__ in ("Cylinder", "Capsule")]
    return max([minimum] + [1.25 * r + 0.005 for r in radii])


class TeleopUI:
    """Builds the scene and panels on ``server`` and keeps them in sync with ``app``."""

    def __init__(self, server: viser.ViserServer, app: TeleopApp, control: ControlThread) -> None:
        self.server = server
        self.app = app
        self.control = control
        self._stop = threading.Event()
        self._markers: dict[str, dict] = {}
        self._visualisers: dict[str, ViserVisualizer] = {}
        self.ring_radius = _ring_radius(app.robot)
        self._build_scene()
        self._build_panels()
        self._thread = threading.Thread(target=self._view_loop, name="view", daemon=True)

    # -- scene ---------------------------------------------------------------------------

    def _visualiser(self, which: str) -> ViserVisualizer:
        robot: Robot = self.app.robot
        visualiser = ViserVisualizer(robot.model, robot.collision_model, robot.visual_model)
        visualiser.initViewer(viewer=self.server)  # our server: never a new one on 0.0.0.0
        color = None if which == "main" else [0.35, 0.65, 1.0, 0.35]
        visualiser.loadViewerModel(rootNodeName=f"/{which}", visual_color=color)
        visualiser.displayCollisions(False)
        visualiser.displayFrames(False)
        return visualiser

    def _build_scene(self) -> None:
        scene = self.server.scene
        scene.add_grid("/grid", width=2.0, height=2.0, cell_size=0.1, position=(0.0, 0.0, -0.4))
        self._visualisers["main"] = self._visualiser("main")
        target = self.app.target
        quaternion = pin.Quaternion(target.rotation)
        self.target_gizmo = scene.add_transform_controls(
            "/target", scale=0.12, position=target.translation,
            wxyz=(quaternion.w, quaternion.x, quaternion.y, quaternion.z))

        @self.target_gizmo.on_update
        def _(event) -> None:
            self._guarded(event, lambda: self.app.set_target(self.target_gizmo.position,
                                                             self.target_gizmo.wxyz))

        look_at = self.app.target.translation  # every new browser looks at the tool
        self.server.initial_camera.position = look_at + np.array([0.9, -0.9, 0.6])
        self.server.initial_camera.look_at = look_at

    # -- panels --------------------------------------------------------------------------

    def _guarded(self, event, action) -> None:
        """Run an operator action; an impossible one becomes a notification, not a traceback."""
        try:
            action()
        except ValueError as error:
            self.notify(event, "Not possible", str(error))

    def notify(self, event, title: str, body: str) -> None:
        clients = [event.client] if event is not None and event.client is not None else \
            list(self.server.get_clients().values())
        for client in clients:
            client.add_notification(title, body, auto_close_seconds=6.0, color="red")

    def _build_panels(self) -> None:
        gui = self.server.gui
        app = self.app
        with gui.add_folder("Controller"):
            ghost_spec = app.specs.get("ghost", "qp:daqp")
            choices = tuple(dict.fromkeys((*CONTROLLER_CHOICES, app.specs["main"], ghost_spec)))
            self.controller_menu = gui.add_dropdown("main", choices,
                                                    initial_value=app.specs["main"])
            self.side_by_side = gui.add_checkbox("side by side", "ghost" in app.loops)
            self.ghost_menu = gui.add_dropdown("ghost", choices, initial_value=ghost_spec)

        @self.controller_menu.on_update
        def _(event) -> None:
            self._guarded(event, lambda: app.set_controller(self.controller_menu.value))

        @self.side_by_side.on_update
        def _(event) -> None:
            self._guarded(event, lambda: app.set_ghost(
                self.ghost_menu.value if self.side_by_side.value else None))

        @self.ghost_menu.on_update
        def _(event) -> None:
            if self.side_by_side.value:
                self._guarded(event, lambda: app.set_ghost(self.ghost_menu.value))

        with gui.add_folder("Constraints"):
            self.hole_distance = gui.add_number("hole at (m)", 0.08, step=0.005,
                                                hint="distance along the constrained link")
            self.add_hole_button = gui.add_button("Add hole")
            self.plane_distance = gui.add_number("plane point at (m)", 0.08, step=0.005)
            self.plane_normal = gui.add_vector3("plane normal", (0.0, 1.0, 0.0), step=0.1)
            self.barrier_offset = gui.add_number("barrier offset (m)", 0.01, min=0.0, step=0.005)
            self.add_plane_button = gui.add_button("Add plane")
            self.add_barrier_button = gui.add_button("Add barrier")
            self.lock_distance = gui.add_number("point lock at (m)", 0.08, step=0.005,
                                                hint="distance along the constrained link")
            self.add_lock_button = gui.add_button("Add point lock")
            self.constraint_menu = gui.add_dropdown("placed", ("(none)",))
            self.remove_button = gui.add_button("Remove")

        self.add_hole_button.on_click(lambda event: self._guarded(
            event, lambda: app.add_hole(self.hole_distance.value)))
        self.add_plane_button.on_click(lambda event: self._guarded(
            event, lambda: app.add_plane(self.plane_distance.value, self.plane_normal.value)))
        self.add_barrier_button.on_click(lambda event: self._guarded(
            event, lambda: app.add_plane(self.plane_distance.value, self.plane_normal.value,
                                         barrier=True, offset=self.barrier_offset.value)))
        self.add_lock_button.on_click(lambda event: self._guarded(
            event, lambda: app.add_point_lock(self.lock_distance.value)))
        self.remove_button.on_click(lambda event: self._guarded(
            event, lambda: app.remove_constraint(self.constraint_menu.value)))

        with gui.add_folder("Control"):
            self.gain_slider = gui.add_slider("drift gain K (1/s)", 0.0, 500.0, 5.0, app.gain)
            self.damping_slider = gui.add_slider("damping lambda", 0.0, 0.2, 0.001, app.damping)
            self.rate_number = gui.add_number("rate (Hz)", app.config.rate, min=50, max=5000, step=50)
            self.home_button = gui.add_button("Home / reset")
        self.gain_slider.on_update(lambda event: self._guarded(
            event, lambda: app.set_gain(self.gain_slider.value)))
        self.damping_slider.on_update(lambda event: self._guarded(
            event, lambda: app.set_damping(self.damping_slider.value)))
        self.rate_number.on_update(lambda event: self._guarded(
            event, lambda: app.set_rate(self.rate_number.value)))
        self.home_button.on_click(lambda event: self._guarded(event, self._home))

        with gui.add_folder("Record"):
            self.record_button = gui.add_button("Start recording")
            self.record_status = gui.add_markdown("not recording")
        self.record_button.on_click(lambda event: self._guarded(event, self._toggle_recording))

        with gui.add_folder("Status"):
            self.status = gui.add_markdown("starting...")

        with gui.add_folder("Plots (last 10 s)"):
            self.plots = {}
            for key, title in (("constraint_error", "constraint error (m)"),
                               ("constraint_velocity", "|C v_c| (m/s)"),
                               ("ee_error", "EE position error (m)"),
                               ("step_time", "step time (us)")):
                self.plots[key] = gui.add_uplot(
                    data=(np.zeros(1), np.zeros(1), np.zeros(1)),
                    series=(uplot.Series(label="t (s)"),
                            uplot.Series(label="main", stroke="#d97706", width=1.5),
                            uplot.Series(label="ghost", stroke="#3b82f6", width=1.5)),
                    title=title, aspect=2.0,
                    scales={"x": uplot.Scale(time=False, auto=True), "y": uplot.Scale(auto=True)})

    def _home(self) -> None:
        self.app.home()
        target = self.app.target
        quaternion = pin.Quaternion(target.rotation)
        self.target_gizmo.position = target.translation
        self.target_gizmo.wxyz = (quaternion.w, quaternion.x, quaternion.y, quaternion.z)

    def _toggle_recording(self) -> None:
        if self.app.recorder is None:
            path = self.app.start_recording()
            self.record_button.label = "Stop recording"
            self.record_status.content = f"recording to `{path}`"
        else:
            path = self.app.stop_recording()
            self.record_button.label = "Start recording"
            self.record_status.content = f"wrote `{path}` (replay: `teleop replay {path}`)"

    # -- the view thread -------------------------------------------------------------------

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _view_loop(self) -> None:
        next_plot = 0.0
        while not self._stop.is_set():
            start = time.perf_counter()
            try:
                snapshot = self.app.snapshot()
                with self.server.atomic():
                    self._draw(snapshot)
                if start >= next_plot:
                    self._plot(snapshot)
                    next_plot = start + 1.0 / PLOT_RATE
            except Exception as error:  # the view must never take the control loop down
                self.status.content = f"view error: {type(error).__name__}: {error}"
            time.sleep(max(0.0, 1.0 / VIEW_RATE - (time.perf_counter() - start)))

    def _draw(self, snapshot: dict) -> None:
        robots = snapshot["robots"]
        if "ghost" in robots and "ghost" not in self._visualisers:
            self._visualisers["ghost"] = self._visualiser("ghost")
        if "ghost" not in robots and "ghost" in self._visualisers:
            self.server.scene.remove_by_name("/ghost")  # noqa: the visualiser's root node
            del self._visualisers["ghost"]
        for which, visualiser in self._visualisers.items():
            visualiser.display(robots[which]["q"])
        self._draw_constraints(snapshot["constraints"])
        self._draw_status(snapshot)

    def _draw_constraints(self, entries: list[dict]) -> None:
        present = {e["id"] for e in entries}
        for entry_id in list(self._markers):
            if entry_id not in present:
                for handle in self._markers.pop(entry_id).values():
                    handle.remove()
        for e in entries:
            markers = self._markers.get(e["id"])
            if markers is None:
                markers = self._markers[e["id"]] = self._create_markers(e)
            geometry = e["geometry"]
            self._update_shape(markers["shape"], geometry)
            markers["point"].position = geometry.point
            # from the point towards where it should be (the error points the other way)
            vector = -ERROR_VECTOR_SCALE * geometry.error
            markers["error"].points = np.array([[geometry.point, geometry.point + vector]])
            markers["error"].visible = float(np.linalg.norm(geometry.error)) > 1e-6
        options = tuple(e["id"] for e in entries) or ("(none)",)
        if tuple(self.constraint_menu.options) != options:
            self.constraint_menu.options = options

    def _add_shape(self, name: str, geometry: ConstraintGeometry):
        """The scene node of a constraint's geometry, drawn as its ``shape`` says."""
        scene = self.server.scene
        if geometry.shape == "ring":
            ring = _ring(geometry.anchor, geometry.axis, self.ring_radius)
            return scene.add_line_segments(f"{name}/ring", ring, geometry.color, thickness=0.004)
        if geometry.shape == "plane":
            return scene.add_box(f"{name}/plane", geometry.color, (0.3, 0.3, 0.001),
                                 opacity=0.3, side="double", wxyz=_wxyz_from_z(geometry.axis),
                                 position=geometry.anchor)
        return scene.add_icosphere(f"{name}/anchor", 0.012, geometry.color, opacity=0.5,
                                   position=geometry.anchor)

    def _update_shape(self, handle, geometry: ConstraintGeometry) -> None:
        if geometry.shape == "ring":  # around the link axis, which turns with the link
            handle.points = _ring(geometry.anchor, geometry.axis, self.ring_radius)
        else:
            handle.position = geometry.anchor

    def _create_markers(self, e: dict) -> dict:
        scene = self.server.scene
        name = f"/constraints/{e['id']}"
        geometry = e["geometry"]
        markers = {"shape": self._add_shape(name, geometry)}
        markers["point"] = scene.add_icosphere(f"{name}/point", 0.006, (20, 20, 20),
                                               position=geometry.point)
        markers["error"] = scene.add_line_segments(f"{name}/error", np.zeros((1, 2, 3)),
                                                   (255, 0, 255), thickness=0.003)
        gizmo = scene.add_transform_controls(f"{name}/gizmo", scale=0.07, position=e["goal"],
                                             disable_rotations=True)
        entry_id = e["id"]

        @gizmo.on_update
        def _(event) -> None:
            self._guarded(event, lambda: self.app.move_constraint(entry_id, gizmo.position))

        markers["gizmo"] = gizmo
        return markers

    def _draw_status(self, snapshot: dict) -> None:
        lines = [f"**control** {self.control.achieved_rate:.0f} Hz achieved "
                 f"(target {snapshot['config'].rate:.0f} Hz), "
                 f"{self.control.deadline_misses} deadline misses"]
        if self.control.error:
            lines.append(f"**control error** {self.control.error}")
        for which, robot in snapshot["robots"].items():
            record, info = robot["record"], robot["info"]
            if record is None:
                continue
            lines.append(
                f"**{which}** `{robot['spec']}` **{record.status}** ({info.method or '-'}): "
                f"constraint {max(record.constraint_error, record.barrier_penetration):.1e} m, "
                f"EE {1e3 * record.ee_position_error:.2f} mm, step {record.step_time_us:.0f} us"
                + (f", {record.message}" if record.message else ""))
        self.status.content = "  \n".join(lines)

    def _plot(self, snapshot: dict) -> None:
        robots = snapshot["robots"]
        main = robots["main"]["trace"]
        ghost = robots.get("ghost", {}).get("trace")
        if main["t"].size < 2:
            return
        for key, plot in self.plots.items():
            other = ghost[key] if ghost is not None and ghost[key].size == main[key].size \
                else np.full(main[key].size, np.nan)
            plot.data = (main["t"], main[key], other)


def run_server(robot: Robot, host: str = "127.0.0.1", port: int = 8080,
               controller: str = "cjm", ghost: str | None = None, rate: float = 1000.0,
               record_dir: str | Path = "sessions") -> tuple[viser.ViserServer, TeleopApp, ControlThread, TeleopUI]:
    """Start the app: server bound to ``host`` (loopback by default), control and view threads."""
    app = TeleopApp(robot, controller=controller, ghost=ghost, rate=rate, record_dir=record_dir)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    control = ControlThread(app)
    ui = TeleopUI(server, app, control)
    control.start()
    ui.start()
    return server, app, control, ui
