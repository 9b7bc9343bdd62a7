"""MuJoCo's profiler clock off while plants step (``teleop/plants/profiler_clock.py``,
docs/design.md section 17.5): the ``mujoco`` package's clock cleared when a plant is made,
a user's timer kept, and a plant's periods the same bit for bit with the clock and
without it (the clock writes only ``MjData.timer``).
"""

from __future__ import annotations

import ctypes
import os

import mujoco
import numpy as np
import pytest

from constraints import Hole
from teleop.plants import MujocoPlant
from teleop.plants.profiler_clock import _mujoco_library, stop_profiler_clock

DT = 1e-3



@pytest.fixture(autouse=True)
def mujoco_library() -> None:
    """libmujoco loadable (Linux), else nothing to check: a skip on a developer's machine,
    a failure in CI (``CI`` set), where every test runs."""
    if _mujoco_library() is None:
        reason = "libmujoco not loadable (not Linux): the package's clock stays"
        if os.environ.get("CI"):
            pytest.fail(f"CI must run this test: {reason}")
        pytest.skip(reason)


def clock_address() -> int | None:
    """MuJoCo's ``mjcb_time`` (None: no clock)."""
    library = _mujoco_library()
    assert library is not None
    return ctypes.c_void_p.in_dll(library, "mjcb_time").value


def periods(plant: MujocoPlant, robot) -> list[np.ndarray]:
    """300 periods under a sweeping command with a moving hole and a stiff damped wall:
    each returned velocity, configuration reached, ``qpos``, ``qvel`` and port force."""
    hole = Hole.on_link(robot, robot.q_home, distance=0.08)
    hole.move_to(hole.center + np.array([0.0, 1e-3, 0.0]), velocity=np.array([0.0, 5e-3, 0.0]))
    hole.tissue_stiffness, hole.tissue_damping = 3000.0, 25.0
    phases = np.arange(robot.model.nv)
    q = robot.q_home.copy()
    out = []
    for k in range(300):
        qd = 0.2 * np.sin(2.0 * np.pi * (k * DT) * (1.0 + 0.3 * phases) + phases)
        moved, q = plant.advance(qd, q, [hole], DT)
        out += [moved, q, plant.mj_data.qpos.copy(), plant.mj_data.qvel.copy(),
                plant.measures().port_forces]
    return out


def test_a_plant_steps_without_the_packages_clock(sda10f):
    plant = MujocoPlant(sda10f, DT)
    assert clock_address() is None
    periods(plant, sda10f)
    step = plant.mj_data.timer[mujoco.mjtTimer.mjTIMER_STEP]
    assert step.number == 600 and step.duration == 0.0  # two physics steps a period


def test_the_periods_are_the_same_bits_with_the_clock(sda10f):
    without = periods(MujocoPlant(sda10f, DT), sda10f)
    clocked = MujocoPlant(sda10f, DT)
    mujoco.set_mjcb_time(None)  # the package's clock back
    try:
        assert clock_address() is not None
        with_clock = periods(clocked, sda10f)
        assert clocked.mj_data.timer[mujoco.mjtTimer.mjTIMER_STEP].duration > 0.0
    finally:
        stop_profiler_clock()
    assert np.max(np.abs(without[4])) > 0.0  # the wall pushes
    assert len(without) == len(with_clock)
    for k, (a, b) in enumerate(zip(without, with_clock)):
        assert a.shape == b.shape and np.array_equal(a, b), k


def test_a_users_timer_stays(sda10f):
    def users_clock() -> float:
        return 0.0

    mujoco.set_mjcb_time(users_clock)
    try:
        MujocoPlant(sda10f, DT)
        assert mujoco.get_mjcb_time() is users_clock
    finally:
        mujoco.set_mjcb_time(None)
        stop_profiler_clock()
    assert clock_address() is None
