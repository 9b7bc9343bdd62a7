"""The viser front end: a thin layer over :class:`web.app.TeleopApp`, one component per
part, each owning its own viser handles (:class:`TeleopUI` holds them; no mixin).

* scene (:mod:`.scene_view`): the robot (:class:`web.robot_view.RobotView`: any URDF,
  meshes or fallbacks; a mobile base moves with its planar root joint), an optional ghost
  robot drawn beside it (``ghost_offset``; zero overlays them), the grid at the robot's
  base; per end effector an input gizmo and, where it differs, the target itself; per
  robot and EE a line from the EE to its target coloured by the step status;
* the placed items, constraints and obstacles alike (:mod:`.placed_markers`: each with
  a gizmo that moves it), each drawn from its own geometry (:mod:`.markers`,
  :mod:`.obstacle_drawer`); the main robot's pairs closer than the detection distance
  highlighted with their witness segments (:mod:`.collision_view`);
* on a physics plant, the wall's force on the instrument at each port, an arrow scaled in
  newtons (:mod:`.port_forces`); a tissue under the tool, force control on it and the
  contact force's arrow and plot (the Force tab, :mod:`.force_panel`);
* the input devices (:mod:`.device_view`): they move in the frame of the view of the
  browser whose camera moved last; their state in the status; the feedback force plotted;
* panels: a status (:mod:`.status_view`: rate, lateness, what limits each robot's EEs in
  words, the one-sided constraints held), then tabs: Teleop (controllers, side by side,
  clutch, motion scale, the active arm's nudges, home, :mod:`.teleop_panel`) and
  Settings (gain, damping, rate, scenes, recording, :mod:`.settings_panel`),
  Constraints, built from the registry's declarations (:mod:`.constraint_form`),
  Collisions (the avoidance's settings, :mod:`.collision_panel`, and the obstacles, from
  the obstacle registry, :mod:`.obstacle_form`): both placed items, one panel
  (:mod:`.placed_panel`), Plots (:mod:`.plots`, uPlot).

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
from collections.abc import Callable
from typing import Any, Literal

import viser

from constraints import CONSTRAINT_TYPES
from constraints.registry import constraint_type
from constraints.collision import OBSTACLE_TYPES

from ..access import Access
from ..app import ControlThread, TeleopApp
from ..constraint_placement import placement_of
from ..inbox import Inbox
from ..pacing import Tally
from ..robot_view import floor_height
from .collision_panel import CollisionSettingsPanel
from .collision_view import PairHighlights
from .constraint_form import ConstraintForm
from .device_view import DevicePanel
from .force_panel import ForcePanel
from .markers import ConstraintDrawer
from .obstacle_drawer import ObstacleDrawer
from .obstacle_form import ObstacleForm
from .placed_markers import Gizmos, PlacedMarkers
from .placed_panel import PlacedActions, PlacedPanel, PlacedWords
from .plots import LivePlots
from .port_forces import PortArrows
from .scene_view import SceneView
from .settings_panel import SettingsPanel
from .shapes import LinkProfile, square_size
from .status_view import StatusPanel
from .teleop_panel import TeleopPanel

#: the colours a notification takes here
NotificationColor = Literal["red", "yellow"]
VIEW_RATE = 30.0  # Hz: robot poses, markers, status
PLOT_RATE = 10.0  # Hz: live plots
STATUS_RATE = 5.0  # Hz: the status text (readable, and light on the browser)
#: what to try on a first run, at the top of the panel until "Got it"
FIRST_RUN_HINT = (
    "1. Drag an arrow or ring of the **gizmo** at the tool: the robot follows.\n"
    "2. **Constraints**: add one where the robot is (the first: an instrument's port), "
    "then drag again: the robot keeps it (the status line names its link).\n"
    "3. **Teleop -> side by side**: a second controller's robot on the left, same target.\n"
    "4. **Plots**: the errors, and with `--plant mujoco` the port force (mN).")


def short_names(frames: tuple[str, ...]) -> dict[str, str]:
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
        #: ``active`` while this thread sets widgets from the app: the callbacks viser runs
        #: synchronously for those assignments do nothing (a thread-local flag, so that an
        #: operator's click, handled on viser's threads meanwhile, is never dropped)
        self._syncing = threading.local()
        robot = app.robot
        #: where each link's geometry is around its axis: rings and collars go outside it
        self.profiles = {link: LinkProfile.of(robot, link) for link in app.constraints.moving_links}
        self.square_sizes = {link: square_size(robot, link) for link in app.constraints.moving_links}
        self.ee_names = short_names(robot.ee_frames)  # what the operator reads per EE
        self.floor = floor_height(app.robot)
        self.notes = list(notes)
        #: what :func:`web.ui.server.run_server` puts in front of the server: the token and
        #: origin check (:mod:`web.access`), the messages' pacing (:mod:`web.pacing`)
        self.access: Access | None = None
        self.pacing: Tally | None = None
        self.scene = SceneView(server, app, self._guarded, self.floor, self._ghost_removed)
        #: the placed items' nodes (constraints: the main robot's, the ghost's; obstacles)
        self.constraint_drawer = ConstraintDrawer(server, robot, self.profiles,
                                                  self.square_sizes, labelled=True)
        self.constraint_markers = PlacedMarkers(
            server, "/constraints", self.constraint_drawer,
            Gizmos(app.constraints.move, self._guarded, "constraint"))
        self.ghost_markers = PlacedMarkers(server, "/ghost/constraints", ConstraintDrawer(
            server, robot, self.profiles, self.square_sizes, labelled=False))
        self.obstacle_markers = PlacedMarkers(
            server, "/obstacles", ObstacleDrawer(server),
            Gizmos(app.collisions.move, self._guarded, "obstacle", scale=0.08))
        self.pair_highlights = PairHighlights(server, robot)
        self.port_arrows = PortArrows(server, self.constraint_drawer.ring_radius_at)
        self.notes += self.scene.views["main"].problems
        self._build_panels()
        server.on_client_connect(self._greet)
        self._thread = threading.Thread(target=self._view_loop, name="view", daemon=True)

    def _ghost_removed(self) -> None:
        """The ghost's nodes went with its root: what was drawn under it is forgotten."""
        self.ghost_markers.forget()
        self.port_arrows.arrows.pop("ghost", None)

    # -- panels --------------------------------------------------------------------------

    def _guarded(self, event: object, action: Callable[[], object], key: object = None,
                 throttled: bool = False) -> None:
        """Post an operator action to the inbox (:mod:`web.inbox`: applied in order on its
        own thread; with a ``key``, the latest wins; ``throttled``, at most 10 a second);
        an impossible one becomes a notification, not a traceback."""
        if getattr(self._syncing, "active", False):
            return
        self.inbox.post(action, key=key, context=event, throttled=throttled)

    def _failed(self, event: Any, error: Exception) -> None:
        """An action from ``event`` (a GUI or scene event; None: none) could not be done:
        tell its browser why."""
        if isinstance(error, ValueError):
            self.notify(event, "Not possible", str(error))
        else:
            self.notify(event, "Error", f"{type(error).__name__}: {error}")

    def notify(self, event: Any, title: str, body: str,
               color: NotificationColor = "red") -> None:
        """Tell the browser of ``event`` (a GUI or scene event; None: every browser)
        ``title`` and ``body``."""
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
        # a wide panel: the plots fit with their axes' labels, the status line is a line
        gui.configure_theme(control_width="large")
        with gui.add_folder("Try this") as self.hint:  # what a first run might try
            gui.add_markdown(FIRST_RUN_HINT)
            gui.add_button("Got it", hint="hide these hints").on_click(
                lambda _: setattr(self.hint, "visible", False))
        with gui.add_folder("Status"):
            self.status_panel = StatusPanel(gui, self.control, self.ee_names,
                                            lambda: self.plots.port_peak,
                                            lambda snapshot: self.device_panel.lines(snapshot),
                                            self.notify)
        self.tabs = gui.add_tab_group()
        with self.tabs.add_tab("Teleop"):
            self.teleop_panel = TeleopPanel(gui, self.app, self.ee_names, self._guarded,
                                            self._sync, self.scene.move_gizmo, self.notify)
            self.device_panel = DevicePanel(self.server, self.app, self.ee_names, self._guarded)
        app = self.app
        with self.tabs.add_tab("Constraints"):
            self.constraint_panel = PlacedPanel(
                gui, {kind: ConstraintForm(constraint_type(kind), app.robot)
                      for kind in CONSTRAINT_TYPES
                      if placement_of(constraint_type(kind)) is not None},
                PlacedActions(lambda kind, values: app.constraints.add(kind, **values),
                              app.constraints.remove, app.constraints.clear),
                PlacedWords("placed", "Remove", "Clear constraints"), self._guarded)
        with self.tabs.add_tab("Collisions"):
            self.collision_settings = CollisionSettingsPanel(gui, app.collisions, self._guarded)
            self.obstacle_panel = PlacedPanel(
                gui, {kind: ObstacleForm(kind) for kind in OBSTACLE_TYPES},
                PlacedActions(lambda kind, values: app.collisions.add(
                    kind, ee=self.teleop_panel.active_ee(), **values),
                    app.collisions.remove, app.collisions.clear),
                PlacedWords("obstacles", "Remove obstacle", "Clear obstacles"), self._guarded)
        with self.tabs.add_tab("Settings"):
            self.settings_panel = SettingsPanel(gui, app, self._guarded, self._scene_loaded)
        force_tab = self.tabs.add_tab("Force")
        with force_tab:
            self.force_panel = ForcePanel(self.server, force_tab, self.app.force, self._guarded,
                                          self._sync)
        self._plot_tab = self.tabs.add_tab("Plots")
        with self._plot_tab:
            self.plot_note = gui.add_markdown("the last 10 s, measured at 50 Hz; with a ghost, "
                                              "since it joined")
        self.plots = LivePlots(self.server, self._plot_tab)
        if self.notes:
            with self.tabs.add_tab("Robot"):
                gui.add_markdown("**Loaded with fallbacks:**\n\n" +
                                 "\n".join(f"* {note}" for note in self.notes))

    def _scene_loaded(self) -> None:
        """Every input and gizmo handle as the app has them after loading a scene, the
        obstacles drawn afresh."""
        self._sync(self.teleop_panel.from_app)
        self._sync(self.settings_panel.from_app)
        self._sync(self.collision_settings.from_app)
        self.obstacle_markers.remove()
        self.scene.move_gizmos()

    def _sync(self, action) -> None:
        """Set widgets from the app without their callbacks acting."""
        self._syncing.active = True
        try:
            action()
        finally:
            self._syncing.active = False

    # -- the view thread -------------------------------------------------------------------

    @property
    def thread(self) -> threading.Thread:
        """The thread this runs on."""
        return self._thread

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
                snapshot = self.app.view.snapshot(history=plot)
                with self.server.atomic():
                    self._draw(snapshot, status=status)
                if status:
                    next_status = start + 1.0 / STATUS_RATE
                if plot:
                    self.plots.draw(snapshot)
                    self.device_panel.draw_plot(snapshot, self._plot_tab,
                                                self.plot_note.order + 0.5)  # the tab's first
                    self.force_panel.draw_plot(snapshot["force"], snapshot["robots"]["main"]["t"])
                    next_plot = start + 1.0 / PLOT_RATE
            except Exception as error:  # the view must never take the control loop down
                self.status_panel.show_error(f"view error: {type(error).__name__}: {error}")
            time.sleep(max(0.0, 1.0 / VIEW_RATE - (time.perf_counter() - start)))

    def _draw(self, snapshot: dict, status: bool = True) -> None:
        robots = snapshot["robots"]
        self.scene.draw(snapshot, self.plots.plotted)
        views = self.scene.views
        placed = {entry["id"]: entry for entry in snapshot["constraints"]}
        goals = {entry_id: entry["goal"] for entry_id, entry in placed.items()}
        self.constraint_markers.draw(placed, goals)
        if "ghost" in views:
            self.ghost_markers.draw(robots["ghost"]["constraints"], goals)
        self.constraint_panel.show_placed(tuple(placed))
        self.port_arrows.draw(robots, views)
        self.force_panel.draw(snapshot["force"], views)
        obstacles = {entry["id"]: entry for entry in snapshot["collisions"]["obstacles"]}
        self.obstacle_markers.draw(obstacles, {entry_id: entry["goal"]
                                               for entry_id, entry in obstacles.items()})
        self.obstacle_panel.show_placed(tuple(obstacles))
        self.pair_highlights.draw(robots["main"]["collision_rows"], robots["main"]["q"],
                                  snapshot["collisions"])
        if status:
            self.status_panel.draw(snapshot)
            self.teleop_panel.show_clutch(snapshot["clutch"])
