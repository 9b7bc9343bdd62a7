"""``teleop sim --ros2``: a simulated robot served on ROS 2 (docs/ros2.md, "A simulated
robot") until Ctrl-C or ``--duration``."""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys

from teleop.limits import MAX_RATE_HZ
from teleop.options import SIM, SIMULATED_PLANT_KINDS

from .arguments import bounded, csv_list
from .plant_options import add_plant_options, given_plant_options
from .sim_ports import DEFAULT_ROBOT, add_port_options, sim_ports


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The sim command's options."""
    parser.add_argument("--ros2", action="store_true", required=True,
                        help="serve the robot on ROS 2 (the one transport offered)")
    parser.add_argument("--robot",
                        help="built-in robot name or URDF path (default: the scenario's, "
                             f"else {DEFAULT_ROBOT})")
    parser.add_argument("--plant", choices=SIMULATED_PLANT_KINDS, default="kinematic",
                        help="the robot's physics: q += v dt, or MuJoCo's servoed drives "
                             "(default: kinematic)")
    parser.add_argument("--rate", type=bounded(float, 1.0, MAX_RATE_HZ, unit="Hz"), default=500.0,
                        help="joint states and control periods per second (default: 500.0)")
    parser.add_argument("--q0", type=csv_list, metavar="RADIANS",
                        help="comma-separated start configuration (default: the robot's home)")
    parser.add_argument("--lockstep", type=bounded(float, 0.0, 1000.0, unit="ms"), default=0.0,
                        metavar="MS",
                        help="each period waits up to MS, once its state is out, for the "
                             "command answering it: the two processes' scheduling out of the "
                             "loop, what the transport alone costs (docs/ros2.md); the loop "
                             "then needs command_latency 0; 0: no wait, a real robot's "
                             "behaviour (default: 0.0)")
    parser.add_argument("--duration", type=bounded(float, 0.0, 1e6, unit="s"),
                        help="seconds to run (default: until Ctrl-C)")
    add_port_options(parser.add_argument_group("ports"))
    add_plant_options(parser.add_argument_group("ROS 2 (docs/ros2.md)"), SIM)


def run(args: argparse.Namespace) -> int:
    """Serve the robot; its node closed on any exit."""
    import numpy as np

    from teleop.plants import MujocoPlant, PlantChoice
    from teleop.plants.ros2.realtime import ROBOT_PRIORITY
    from teleop.plants.ros2.simulated_robot import SimulatedRos2Robot

    robot, constraints, q0 = sim_ports(args)
    if args.q0 is not None:
        try:
            q0 = np.array([float(v) for v in args.q0])
        except ValueError:
            raise ValueError(f"--q0 must be numbers, got {','.join(args.q0)}") from None
        if q0.shape != (robot.model.nq,) or not np.all(np.isfinite(q0)):
            raise ValueError(f"--q0 needs {robot.model.nq} finite numbers, got {len(q0)}")
    settings = PlantChoice.with_options(given_plant_options(args), "ros2").ros2
    assert settings is not None  # the ros2 plant has its settings
    if args.realtime_priority is None:  # the sim plays the robot: its controller's priority
        settings = dataclasses.replace(settings, realtime_priority=ROBOT_PRIORITY)
    plant = MujocoPlant(robot, 1.0 / args.rate) if args.plant == "mujoco" else None
    sim = SimulatedRos2Robot(robot, args.rate, settings, plant, q0, constraints,
                             args.port_forces, args.lockstep / 1e3)
    signal.signal(signal.SIGTERM, lambda *_: sim.stop())
    ports = (f", {len(sim.port_force_writers)} port forces on {args.port_forces}/port<i>"
             if sim.port_force_writers else "")
    print(f"teleop sim: {robot.name} on ROS 2 domain {sim.node.domain}: "
          f"{settings.state_topic} at {args.rate:g} Hz, commands on {settings.commands}"
          f"{ports}; threads {sim.realtime}", file=sys.stderr, flush=True)
    try:
        sim.run(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        sim.close()
        print(f"teleop sim: {sim.jitter_words()}", file=sys.stderr, flush=True)
    return 0
