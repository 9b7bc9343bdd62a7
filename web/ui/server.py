"""Starting the browser UI: the server, the app, the control and view threads."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Sequence

import viser

from teleop.inputs import InputSource
from teleop.plants import PlantSettings
from teleop.plants.ros2.realtime import LOOP_PRIORITY
from teleop.plants.ros2.settings import Ros2Settings
from teleop.robots import Robot

from ..access import make_token, require_access
from ..pacing import pace_messages
from ..shared_priority import SharedPriority, is_realtime
from ..app import ControlThread, TeleopApp
from .core import TeleopUI


def run_server(robot: Robot, host: str = "127.0.0.1", port: int = 8080,
               controller: str = "cjm", ghost: str | None = None, rate: float = 1000.0,
               record_dir: str | Path = "sessions", scene: dict | None = None,
               notes: list[str] | tuple[str, ...] = (), scene_dir: str | Path = "scenes",
               token: str | None = None, plant: str = "kinematic",
               plant_settings: PlantSettings | None = None,
               wall_stiffness: float | None = None, collisions: bool = True,
               collision_settings: dict | None = None,
               inputs: Sequence[InputSource] = (), input_timeout: float | None = None,
               acceleration_limits: bool = True, jerk_limit: float | None = None,
               task_mode: str = "auto", ros2_settings: Ros2Settings | None = None,
               realtime_priority: int = LOOP_PRIORITY
               ) -> tuple[viser.ViserServer, TeleopApp, ControlThread, TeleopUI]:
    """Start the app: server bound to ``host`` (loopback by default), control and view
    threads. ``scene`` (a scene dict for this robot) is applied before anything runs.
    The page reads and writes files in ``scene_dir`` and ``record_dir`` only; a websocket
    whose Origin is not the page's own gets nothing, nor, with a ``token`` ("auto": a
    random one, then ``ui.access.token``), one that does not present it
    (:mod:`web.access`).
    ``plant``, ``plant_settings``, ``wall_stiffness``, ``ros2_settings``: what the loops
    run on;
    ``collisions``, ``collision_settings``: the collision avoidance;
    ``acceleration_limits``: the robot's joint acceleration limits kept (on by default),
    ``jerk_limit``: a jerk limit on every joint (rad/s^3; needs the acceleration limits)
    (:class:`web.app.TeleopApp`); ``task_mode``: what the operator commands of each EE
    (:meth:`TeleopApp.set_task_mode`, docs/design.md section 20; a scene's own wins);
    ``inputs``: the devices that drive the EEs, each its own (docs/design.md section 19),
    released after ``input_timeout`` s of silence (default 0.1 s); the caller closes them
    (:meth:`web.app.devices.InputDevices.close`); ``realtime_priority``: the control
    thread's ``SCHED_FIFO`` priority (0: ordinary scheduling; over ROS 2 the plant's
    settings choose, :class:`web.app.ControlThread`); while the control thread runs
    real-time, the server's own threads besides run ``SCHED_FIFO`` below it
    (:mod:`web.shared_priority`)."""
    before = set(threading.enumerate())
    app = TeleopApp(robot, controller=controller, ghost=ghost, rate=rate, record_dir=record_dir,
                    scene_dir=scene_dir, plant=plant, plant_settings=plant_settings,
                    wall_stiffness=wall_stiffness, collisions=collisions,
                    collision_settings=collision_settings,
                    acceleration_limits=acceleration_limits, jerk_limit=jerk_limit,
                    ros2_settings=ros2_settings)
    app.robots.set_task_mode(task_mode)
    if scene is not None:
        app.scenes.apply(scene)
    if input_timeout is not None:
        app.devices.set_input_timeout(input_timeout)
    for source in inputs:
        app.devices.attach(source)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    access = require_access(server, None if token is None else make_token(token), host)
    pacing = pace_messages(server)  # what one page's messages may cost (web/pacing.py)
    # a page that connected before the check was in place (nothing is served yet)
    # reconnects, and is checked
    server._websock_server.disconnect_all_clients()
    control = ControlThread(app, realtime_priority)
    ui = TeleopUI(server, app, control, notes=notes)
    ui.access, ui.pacing = access, pacing
    control.start()
    ui.start()
    receivers = ({f"input {source.name}" for source in inputs}
                 | {source.name for source in inputs})
    owned = [ui.thread, ui.inbox.thread, server._websock_server._server_thread,
             *(thread for thread in threading.enumerate()
               if thread not in before and thread.name in receivers)]
    control.shared = SharedPriority(owned, [server._thread_executor])
    control.shared.follow(is_realtime(control.thread.native_id or 0))
    return server, app, control, ui

