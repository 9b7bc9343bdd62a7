"""The hole held over ROS 2 against the in-process loop, with the wire's jitter beside each
run (issue 35 item 4, docs/ros2.md "Jitter, and the commands in flight").

trocar-circle, CJM, 500 Hz: first in-process with 0, 1 and 2 periods of command latency
(``Imperfections(latency=N)``), then ``--runs`` times over DDS on the loopback interface:
``teleop sim --ros2`` in a process of its own (the kinematic robot at the scenario's q0,
or with ``--plant mujoco`` the MuJoCo robot with the scenario's hole and its wall) and
``run_plan`` on ``PlantChoice("ros2")`` in this one, ``Ros2Settings.command_latency`` as
``--command-latency`` says. Each DDS run prints the hole error, the wall-clock time the
run took and the sim's jitter counts (periods that held the last command, commands
superseded in their period, late periods).

Run:  OPENBLAS_NUM_THREADS=1 python docs/measure_ros2_jitter.py [--plant kinematic|mujoco]
      [--runs 3] [--duration 3] [--command-latency 1] [--lockstep MS] [--domain 150]
      [--realtime-priority N]  (0: both processes' threads ordinary; default: each
      side's own, the loop 40 below the robot's 50)
(the machine's other work moves these figures: the jitter counts say by how much)
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: Cyclone on the loopback interface only (as tests/test_ros2_wire.py configures it)
LOOPBACK = ("<General><Interfaces><NetworkInterface name='lo'/></Interfaces></General>"
            "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
            "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex>"
            "<Peers><Peer address='127.0.0.1'/></Peers></Discovery>")

RATE = 500.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plant", choices=("kinematic", "mujoco"), default="kinematic")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--duration", type=float, default=3.0)
    parser.add_argument("--command-latency", type=int, default=1)
    parser.add_argument("--domain", type=int, default=150)
    parser.add_argument("--lockstep", type=float, default=0.0,
                        help="teleop sim --lockstep MS (0: the robot does not wait)")
    parser.add_argument("--realtime-priority", type=int, default=None,
                        help="SCHED_FIFO priority of both sides' threads (0: ordinary; "
                             "default: each side's own, the loop 40, the robot 50)")
    args = parser.parse_args()
    os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK)

    from teleop.experiments.compare import run_plan
    from teleop.experiments.scenarios import load_scenario
    from teleop.loop import LoopConfig
    from teleop.plants.choice import PlantChoice
    from teleop.plants.imperfect import Imperfections
    from teleop.plants.ros2.settings import Ros2Settings

    plan = load_scenario("trocar-circle")
    config = LoopConfig(rate=RATE)
    for latency in (0, 1, 2):
        result = run_plan(plan, "cjm", config, args.duration,
                          imperfections=Imperfections(latency=latency),
                          plant=PlantChoice(args.plant))
        print(f"in-process {args.plant}, latency {latency}: "
              f"{result.metrics()['constraint_error_max_m'] * 1e6:.3f} um", flush=True)
    where = (["--plant", "mujoco", "--scenario", "trocar-circle"] if args.plant == "mujoco"
             else ["--q0", ",".join(repr(float(v)) for v in plan.q0)])
    # this process's topics: another ROS 2 program on the same domain never mixes in
    topics = {"joint_states": f"/run{os.getpid()}/joint_states",
              "command_topic": f"/run{os.getpid()}/forward_velocity_controller/commands"}
    priority = ([] if args.realtime_priority is None
                else ["--realtime-priority", str(args.realtime_priority)])
    loop_priority = ({} if args.realtime_priority is None
                     else {"realtime_priority": args.realtime_priority})
    for run in range(args.runs):
        domain = (args.domain + run) % 233
        sim = subprocess.Popen([sys.executable, "-m", "teleop", "sim", "--ros2", "--rate",
                                str(RATE), "--ros-domain", str(domain), "--lockstep",
                                str(args.lockstep), *priority, "--joint-states",
                                topics["joint_states"], "--command-topic",
                                topics["command_topic"], *where],
                               cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                               stderr=subprocess.PIPE, text=True)
        try:
            start = time.monotonic()
            settings = Ros2Settings(domain=domain, start_timeout=60.0, stale_after=1.0,
                                    command_latency=args.command_latency,
                                    **loop_priority, **topics)
            result = run_plan(plan, "cjm", config, args.duration,
                              plant=PlantChoice("ros2", ros2=settings))
            wall = time.monotonic() - start
        finally:
            sim.terminate()
            _, err = sim.communicate()
        counts = err.strip().splitlines()[-1] if err.strip() else "(the sim printed nothing)"
        print(f"over DDS {args.plant}, command_latency {args.command_latency}, lockstep "
              f"{args.lockstep:g} ms, realtime priority "
              f"{settings.realtime_priority if priority else 'default'}, run {run}: "
              f"{result.metrics()['constraint_error_max_m'] * 1e6:.3f} um in {wall:.2f} s; "
              f"{counts}", flush=True)


if __name__ == "__main__":
    main()
