"""A network master over the UDP protocol: the UI core runs headless here, a hole holds
on link 6, and this script plays the master: a 5 s circle (1 cm radius, in the plane of
the operator's view) streamed at 1 kHz, the feedback read back; then it goes silent and
the watchdog stops the robot (docs/design.md section 19, docs/inputs.md). Every datagram
carries an HMAC of the key the receiver drew (``master.key``; ``teleop web`` prints it).

Run:  python examples/11_network_master.py [--seconds 60]
      (--seconds: how long the circles are streamed, one circle per 5 s; the closing note's
      1 kHz loopback figures are from --seconds 60)
Or drive a running page: start `teleop web --input udp:9870` (it prints the "network
master key"), open it, place a hole if you like, then
      python examples/11_network_master.py --drive 9870 --key KEY
      (--key-file FILE for a key given to teleop web by --input-key FILE): the same circles
      move the page's target; the page's status shows the master and its feedback force.
"""

import argparse
import math
import time

import numpy as np

from teleop import load_robot
from teleop.inputs import MasterClient, UdpMaster
from teleop.inputs.protocol import read_key_file
from web.app import ControlThread, TeleopApp

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--seconds", type=float, default=5.0)
parser.add_argument("--drive", type=int, metavar="PORT",
                    help="drive a running `teleop web --input udp:PORT` instead of a headless app")
parser.add_argument("--key", help="the network master key `teleop web` printed (hex)")
parser.add_argument("--key-file", help="the key file given to `teleop web --input-key`")
args = parser.parse_args()
RATE, SECONDS, RADIUS, PERIOD = 1000.0, args.seconds, 0.01, 5.0


def circle(k: int) -> tuple[float, float, float]:
    """The master's position at sample ``k`` (m, the operator's view frame): circles of
    :data:`RADIUS` from where the master starts, one per :data:`PERIOD` s."""
    angle = 2.0 * math.pi * k / (RATE * PERIOD)
    return (RADIUS * (math.cos(angle) - 1.0), RADIUS * math.sin(angle), 0.0)


if args.drive is not None:  # a running page: stream the circles to it, read its feedback
    if (args.key is None) == (args.key_file is None):
        parser.error("--drive needs the page's key: --key KEY or --key-file FILE")
    try:
        client = MasterClient(args.drive, key=args.key if args.key is not None
                              else read_key_file(args.key_file))
    except ValueError as error:  # a key that is not one, a missing file
        parser.error(str(error))
    forces = []
    start = time.perf_counter()
    for k in range(int(RATE * SECONDS) + 1):
        client.send_pose(circle(k))
        feedback = client.feedback()
        if feedback is not None:
            forces.append(np.linalg.norm(feedback.wrench[:3]))
        time.sleep(max(0.0, start + (k + 1) / RATE - time.perf_counter()))
    client.close()
    print(f"sent {client.sequence} commands to 127.0.0.1:{args.drive}; feedback received: "
          f"{len(forces)}" + (f", force max {max(forces):.3f} N" if forces else
                               " (none: is the key the page's, and its port this one?)"))
    raise SystemExit(0)

app = TeleopApp(load_robot("sda10f"), controller="cjm", rate=1000.0)
app.constraints.add("hole", distance=0.08)
master = UdpMaster(port=0)  # any free port on 127.0.0.1, a key drawn at random
app.devices.attach(master)
control = ControlThread(app)
control.start()

client = MasterClient(master.port, key=master.key)  # the master holds the same key
errors, holes, forces = [], [], []
start = time.perf_counter()
for k in range(int(RATE * SECONDS) + 1):
    client.send_pose(circle(k))
    if k % 10 == 0 and k > 500:  # after the first half second, every 10 ms
        errors.append(app.view.limitation().distance)
        record = app.robots.last_records["main"]
        holes.append(record.constraint_error if record is not None else 0.0)
    feedback = client.feedback()
    if feedback is not None:
        forces.append(np.linalg.norm(feedback.wrench[:3]))
    time.sleep(max(0.0, start + (k + 1) / RATE - time.perf_counter()))

silent_from = time.perf_counter()  # the master goes silent: the watchdog releases it
while app.devices[0].state.name != "HELD" or np.max(np.abs(app.robots.loops["main"].last_qd)) >= 1e-3:
    if time.perf_counter() - silent_from > 10.0:
        raise SystemExit("the robot did not stop within 10 s of the master's silence")
    time.sleep(0.001)
stopped_ms = 1e3 * (time.perf_counter() - silent_from)
control.stop()
client.feedback()
stats, reason = master.statistics(), app.devices[0].reason
app.devices.close()
client.close()

print(f"sent {client.sequence} commands, received {stats['received']}, applied "
      f"{stats['applied']}, superseded {stats.get('superseded', 0)}, dropped {stats['dropped']}, "
      f"lost {stats.get('lost', 0)}, hello {stats.get('hello', 0)} (sent before the launch "
      "was heard: answered, not applied)")
print(f"feedback received: {len(client.received)}, force max {max(forces):.3f} N")
print(f"latency arrival-to-command p50 {stats['latency_p50_ms']:.3f} ms, "
      f"p99 {stats['latency_p99_ms']:.3f} ms")
print(f"tracking error RMS {1e3 * math.sqrt(np.mean(np.square(errors))):.3f} mm, "
      f"max {1e3 * max(errors):.3f} mm; hole error max {1e6 * max(holes):.3f} um")
print(f"master silent: robot stopped {stopped_ms:.0f} ms later ({reason})")
