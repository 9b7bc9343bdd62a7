"""A CRTK master arm in its own process for tests/test_ros2_master.py: publishes
``<ns>/servo_cp`` at 200 Hz, the stylus moved by (0, 2 cm, 0) over its first second then
held, until its standard input closes; meanwhile reads ``<ns>/servo_cf``. Then prints one
JSON line: the wrenches received, the largest force, the last two wrenches.

Usage: python crtk_master.py DOMAIN NAMESPACE"""

from __future__ import annotations

import json
import sys
import threading
import time

import numpy as np

from teleop.plants.ros2.messages import Point, Pose, PoseStamped, WrenchStamped
from teleop.plants.ros2.node import Ros2Node


def main() -> None:
    domain, namespace = int(sys.argv[1]), sys.argv[2]
    node = Ros2Node(domain)
    poses = node.writer(namespace + "/servo_cp", PoseStamped)
    wrenches = node.reader(namespace + "/servo_cf", WrenchStamped)
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    received, largest, previous, last = 0, 0.0, [0.0] * 6, [0.0] * 6

    def read() -> None:
        nonlocal received, largest, previous, last
        for sample in wrenches.take(256):
            if isinstance(sample, WrenchStamped):
                f, t = sample.wrench.force, sample.wrench.torque
                previous, last = last, [f.x, f.y, f.z, t.x, t.y, t.z]
                received += 1
                largest = max(largest, float(np.linalg.norm(last[:3])))

    while poses.get_publication_matched_status().current_count == 0 and not done.is_set():
        time.sleep(0.005)  # the page's reader found: the first sample it gets is the start
    start = time.monotonic() + 0.5  # still for half a second, then the motion
    while not done.is_set():
        s = min(max(time.monotonic() - start, 0.0), 1.0)
        poses.write(PoseStamped(pose=Pose(position=Point(0.1, 0.02 * s, 0.3))))
        read()
        time.sleep(0.005)
    time.sleep(0.3)
    read()
    print(json.dumps({"received": received, "largest": largest, "previous": previous,
                      "last": last}), flush=True)
    node.close()


if __name__ == "__main__":
    main()
