"""The compiled CJM's ``constraint_rows`` describe the configuration it last solved at, as
the Python step's do (found by the command fuzz: after a compiled step, the rows came from
stale kinematics, b off by 52.8 on ur5_instrument, while the command itself was right)."""

from __future__ import annotations

import numpy as np

from constraints import Hole
from teleop import load_robot
from teleop.controller_specs import make_controller


def test_compiled_rows_match_the_python_steps_rows_after_a_solve():
    robot = load_robot("ur5_instrument")
    link = next(iter(robot.constrained_links))
    hole = Hole.on_link(robot, robot.q_home, distance=0.05, link=link)
    twist = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    compiled = make_controller("cjm", robot, [hole], time_budget=None)
    python = make_controller("cjm:python", robot, [hole], time_budget=None)
    compiled.solve(robot.q_home, twist)
    python.solve(robot.q_home, twist)
    A_compiled, b_compiled = compiled.constraint_rows([0])
    A_python, b_python = python.constraint_rows([0])
    np.testing.assert_allclose(A_compiled, A_python, atol=1e-12)
    np.testing.assert_allclose(b_compiled, b_python, atol=1e-12)
