"""A robot with a body: the CJM holding a trocar on the MuJoCo physics plant.

The ``paper-hole`` scenario on the simulated sda10f (servo drives at 2 kHz under the 1 kHz
loop, gravity compensated) carrying a 0.5 kg payload the controller does not know of. The
abdominal wall at the port pushes on the instrument with 1 N/mm; the script prints the
largest port force, the tissue displacement it came with, and the hole error, beside the
same run on the ideal integrator.

Run:  python examples/08_physics_plant.py [--seconds S]   (default 3 s)
"""

import argparse

import numpy as np

from teleop.controller_specs import make_controller
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, TeleopLoop
from teleop.plants import MujocoPlant, PlantSettings

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--seconds", type=float, default=3.0, help="simulated seconds")
args = parser.parse_args()

plan = load_scenario("paper-hole")
config = LoopConfig(rate=1000.0)
for plant_name in ("kinematic", "mujoco"):
    constraints = plan.make_constraints()
    controller = make_controller("cjm", plan.robot, constraints, dt=config.dt)
    plant = (MujocoPlant(plan.robot, config.dt, PlantSettings(payload=0.5))
             if plant_name == "mujoco" else None)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config, plant=plant)
    hole_error, force, displacement = 0.0, 0.0, 0.0
    for i in range(int(args.seconds * config.rate)):
        record = loop.tick(plan.target((i + 1) * config.dt))
        hole_error = max(hole_error, record.constraint_error)
        if record.plant is not None and record.plant.port_force > force:
            force = record.plant.port_force
            displacement = float(np.max(record.plant.port_displacements))
    print(f"{plant_name:>9} plant: hole error max {1e3 * hole_error:.4f} mm", end="")
    if plant is not None:
        stiffness = constraints[0].tissue_stiffness
        print(f", port force max {force:.4f} N at a tissue displacement of "
              f"{1e3 * displacement:.4f} mm (wall {stiffness / 1e3:g} N/mm)", end="")
    print()
