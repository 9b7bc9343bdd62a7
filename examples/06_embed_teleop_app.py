"""Embed the teleoperation UI in your own viser server and add your own controls.

``web.ui.run_server`` starts the whole UI (the control thread at 1 kHz, the 30 Hz view
thread) and returns the ``viser.ViserServer``, the ``TeleopApp`` core and both threads.
Anything else goes on the same server: here a hole 8 cm along link 6 through the app's
API, and a folder of our own with a button that nudges the target 1 cm up and a live
readout of the hole error. Open the printed address in a browser.

Run:  python examples/06_embed_teleop_app.py [--port 8080] [--seconds N]
      (runs until Ctrl-C; with --seconds it stops by itself after N seconds)
"""

import argparse
import tempfile
import time

import numpy as np
import pinocchio as pin

from teleop import load_robot
from web.ui import run_server

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--port", type=int, default=0, help="0: any free port")
parser.add_argument("--seconds", type=float, help="stop after this long (default: Ctrl-C)")
args = parser.parse_args()

robot = load_robot("sda10f")
server, app, control, ui = run_server(robot, host="127.0.0.1", port=args.port,
                                      controller="cjm", ghost="qp:daqp",
                                      record_dir=tempfile.mkdtemp(prefix="cjm-sessions-"))
hole_id = app.constraints.add("hole", distance=0.08)  # the same as the "Add hole" button
print(f"UI on http://127.0.0.1:{server.get_port()} ({robot.name}, cjm + ghost qp:daqp), "
      f"added {hole_id}", flush=True)

with server.gui.add_folder("My example"):
    nudge = server.gui.add_button("Nudge target 1 cm up")
    readout = server.gui.add_markdown("...")


def nudge_up() -> None:
    """Move the shared target 1 cm up (world z): the robot and its ghost follow."""
    target = app.view.snapshot()["target"]
    x, y, z, w = pin.Quaternion(target.rotation).coeffs()
    app.console.set_target(target.translation + np.array([0.0, 0.0, 0.01]), (w, x, y, z))


nudge.on_click(lambda event: nudge_up())

z0 = app.view.snapshot()["target"].translation[2]
nudge_at = 0.5  # press our button once ourselves, so a short run moves the robot
start = time.monotonic()
try:
    while args.seconds is None or time.monotonic() - start < args.seconds:
        time.sleep(0.25)
        if nudge_at is not None and time.monotonic() - start >= nudge_at:
            nudge_up()
            nudge_at = None
        robots = app.view.snapshot()["robots"]  # traces: the last 10 s at 50 Hz
        readout.content = "  \n".join(
            f"**{which}** hole error max {state['trace']['constraint_error'].max(initial=0):.1e} m"
            for which, state in robots.items())
except KeyboardInterrupt:
    pass
finally:
    snapshot = app.view.snapshot()
    ui.stop()
    control.stop()
    server.stop()

print(f"ran {snapshot['robots']['main']['t']:.2f} s of control, "
      f"{control.achieved_rate:.0f} Hz achieved, {control.deadline_misses} deadline misses; "
      f"target moved {1e3 * (snapshot['target'].translation[2] - z0):.1f} mm up")
for which, state in snapshot["robots"].items():
    hole_error = state["trace"]["constraint_error"].max(initial=0.0)
    print(f"{which:5s} ({state['spec']}): hole error max = {hole_error:.2e} m, "
          f"EE position error now = {state['record'].ee_position_error:.2e} m")
