"""The plant's period in one compiled call (``teleop/plants/plant_period.c``,
docs/design.md section 17.5) against the same plant's period in Python around one
``mj_step(m, d, nstep)`` call with the compiled walls (the reference
tests/test_compiled_wall.py holds to the Python walls): the same arithmetic in the same
order, so every number is equal bit for bit, over runs where the holes move, their walls
stiffen, the set of holes changes and the drives saturate.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from constraints import Hole
from teleop.plants import Imperfections, MujocoPlant, PlantSettings
from teleop.plants.compiled_period import CompiledPeriod
from teleop.plants.walls import PortWall, register_wall

DT = 1e-3


def commands(nv: int, periods: int, amplitude: float) -> list[np.ndarray]:
    """A joint-velocity command sweeping every joint (rad/s)."""
    phases = np.arange(nv)
    return [amplitude * np.sin(2.0 * np.pi * (k * DT) * (1.0 + 0.3 * phases) + phases)
            for k in range(periods)]


def moving_hole(robot, link: str | None = None) -> Hole:
    """A hole 8 cm along ``link``, 1 mm off the axis, moving at 5 mm/s, a stiff damped wall."""
    hole = Hole.on_link(robot, robot.q_home, distance=0.08, **({"link": link} if link else {}))
    hole.move_to(hole.center + np.array([0.0, 1e-3, 0.0]), velocity=np.array([0.0, 5e-3, 0.0]))
    hole.tissue_stiffness = 3000.0
    hole.tissue_damping = 25.0
    return hole


def run(plant: MujocoPlant, robot, holes: list[Hole], amplitude: float) -> list[tuple]:
    """Each period's returned velocity, the configuration it reaches (Pinocchio's
    integration of it, to the last bit), the simulated joints and the measures, while the
    holes change: from period 100 each centre moves 0.2 mm, from 200 each wall stiffens,
    from 300 the last hole is gone."""
    q = robot.q_home.copy()
    out = []
    given = list(holes)
    for k, qd in enumerate(commands(robot.model.nv, 400, amplitude)):
        if k == 100:
            for hole in holes:
                hole.move_to(hole.center + np.array([2e-4, 0.0, 0.0]), velocity=hole.velocity)
        if k == 200:
            for hole in holes:
                hole.tissue_stiffness = 4500.0
        if k == 300:
            given = given[:-1]
        moved, reached = plant.advance(qd, q, given, DT)
        assert np.array_equal(reached, pin.integrate(robot.model, q, moved * DT)), k
        q = reached
        m = plant.measures()
        out.append((moved, reached, plant.mj_data.qpos.copy(), m.port_forces,
                    m.port_spring_forces,
                    m.port_displacements, m.torque_ratio, m.saturated, m.contacts,
                    m.contact_depth, m.interface_fault, m.interface_stopped,
                    m.tool_wrenches.shape, m.contact_forces.shape, m.contact_depths.shape))
    return out


def plants(robot, settings: PlantSettings) -> tuple[MujocoPlant, MujocoPlant]:
    """A plant with the compiled period, and one without (its Python around mj_step)."""
    compiled, reference = MujocoPlant(robot, DT, settings), MujocoPlant(robot, DT, settings)
    assert isinstance(compiled._period, CompiledPeriod)
    reference._period = None
    return compiled, reference


def assert_same(compiled: list[tuple], reference: list[tuple]) -> None:
    assert len(compiled) == len(reference)
    for k, (ours, theirs) in enumerate(zip(compiled, reference)):
        for a, b in zip(ours, theirs):
            if isinstance(a, np.ndarray):
                assert a.shape == b.shape and np.array_equal(a, b), (k, a, b)
            else:
                assert type(a) is type(b) and a == b, (k, a, b)


@pytest.mark.parametrize("robot_name", ["sda10f", "ur5_instrument"])
def test_one_hole_moving_stiffening_then_gone(robot_name, request):
    robot = request.getfixturevalue(robot_name)
    compiled, reference = plants(robot, PlantSettings())
    runs = [run(plant, robot, [moving_hole(robot)], 0.2) for plant in (compiled, reference)]
    assert max(np.max(np.abs(r[3]), initial=0.0) for r in runs[1]) > 1.0  # the wall pushes (N)
    assert any(r[3].shape == (0, 3) for r in runs[1])  # and is gone at the end
    assert_same(*runs)


def test_two_holes_on_the_dual_robot(dual):
    compiled, reference = plants(dual, PlantSettings())
    runs = [run(plant, dual, [moving_hole(dual, link) for link in dual.constrained_links], 0.2)
            for plant in (compiled, reference)]
    assert runs[1][0][3].shape == (2, 3) and runs[1][-1][3].shape == (1, 3)
    assert_same(*runs)


def test_two_holes_on_the_mobile_robot(mobile):
    """A planar base (MuJoCo's x, y, heading against Pinocchio's x, y, cos, sin) while it
    drives and turns: the command mapped in and ``qpos`` mapped out around the call."""
    compiled, reference = plants(mobile, PlantSettings())
    runs = [run(plant, mobile, [moving_hole(mobile, link) for link in mobile.constrained_links],
                0.2) for plant in (compiled, reference)]
    assert runs[1][0][3].shape == (2, 3) and runs[1][-1][3].shape == (1, 3)
    headings = [np.arctan2(r[1][3], r[1][2]) for r in runs[1]]
    assert max(headings) - min(headings) > 0.01  # the base turned (rad)
    assert_same(*runs)


def test_saturated_drives_under_a_payload(sda10f):
    """A fast sweep with 3 kg at the EE and weak drives: the torque ratio reaches 1."""
    settings = PlantSettings(payload=3.0, servo_bandwidth=40.0)
    compiled, reference = plants(sda10f, settings)
    runs = [run(plant, sda10f, [moving_hole(sda10f)], 2.0) for plant in (compiled, reference)]
    assert any(r[7] for r in runs[1])
    assert_same(*runs)


class PythonWalledHole(Hole):
    """A hole whose wall has no compiled form: its periods run split in Python."""


class PythonPortWall(PortWall):
    def compiled_parameters(self, hole: Hole) -> None:  # type: ignore[override]
        return None


register_wall(PythonWalledHole, PythonPortWall())


def test_a_period_split_in_python_leaves_no_force_to_the_compiled_ones(sda10f):
    """100 periods with a hole whose wall only Python applies (the physics split, the
    forces in ``qfrc_applied``), then 100 with an ordinary hole (the compiled period):
    bit for bit the plant that runs every period in Python, which clears the forces at
    each period's start."""
    compiled, reference = plants(sda10f, PlantSettings())
    outcomes = []
    for plant in (compiled, reference):
        python_walled = moving_hole(sda10f)
        python_walled.__class__ = PythonWalledHole
        q, moved = sda10f.q_home.copy(), []
        for k, qd in enumerate(commands(sda10f.model.nv, 200, 0.2)):
            moved.append(plant.actuate(qd, q, [python_walled if k < 100 else moving_hole(sda10f)]))
            q = pin.integrate(sda10f.model, q, moved[-1] * DT)
        outcomes.append((moved, plant.mj_data.qpos.copy()))
    assert np.abs(compiled.mj_data.qfrc_applied).max() == 0.0
    for ours, theirs in zip(*(moved for moved, _ in outcomes)):
        assert np.array_equal(ours, theirs)
    assert np.array_equal(outcomes[0][1], outcomes[1][1])


class LateWalledHole(Hole):
    """A hole whose type is given a wall of its own after its periods began."""


def test_a_wall_registered_between_periods_takes_over(sda10f):
    """100 periods with the wall LateWalledHole inherits (compiled), then its own wall,
    registered then, without a compiled form (the periods split in Python): bit for bit
    the plant that runs every period in Python, which looks the wall up each period."""
    compiled, reference = plants(sda10f, PlantSettings())
    hole = moving_hole(sda10f)
    hole.__class__ = LateWalledHole
    runs: list[list[np.ndarray]] = [[], []]
    q = [sda10f.q_home.copy(), sda10f.q_home.copy()]
    for k, qd in enumerate(commands(sda10f.model.nv, 200, 0.2)):
        if k == 100:
            register_wall(LateWalledHole, PythonPortWall())
        for i, plant in enumerate((compiled, reference)):
            moved = plant.actuate(qd, q[i], [hole])
            q[i] = pin.integrate(sda10f.model, q[i], moved * DT)
            runs[i] += [moved, plant.mj_data.qpos.copy(), plant.measures().port_forces]
    assert compiled._forces_applied  # the last periods were split in Python
    for ours, theirs in zip(*runs):
        assert np.array_equal(ours, theirs)


def test_no_compiled_period_where_python_stands_between(sda10f):
    """An interface that checks, or imperfections: the period stays in Python."""
    assert MujocoPlant(sda10f, DT, PlantSettings(interface_limits="count"))._period is None
    assert MujocoPlant(sda10f, DT, imperfections=Imperfections(latency=1))._period is None
    assert MujocoPlant(sda10f, DT, compiled_walls=False)._period is None


def test_commands_of_any_layout_or_dtype_are_copied_in(sda10f):
    """A strided view and an integer array reach the C side as the float64 vector they
    hold: the same periods as a contiguous command."""
    nv = sda10f.model.nv
    plants_ = [MujocoPlant(sda10f, DT) for _ in range(3)]
    wide = np.zeros((nv, 2))
    q = sda10f.q_home.copy()
    for k in range(50):
        command = np.full(nv, (k % 3) - 1, dtype=np.int64)  # -1, 0, 1 rad/s
        wide[:, 0] = command
        moved = [plant.actuate(given, q, []) for plant, given in
                 zip(plants_, (command.astype(float), wide[:, 0], command))]
        assert all(np.array_equal(m, moved[0]) for m in moved[1:])
        q = pin.integrate(sda10f.model, q, moved[0] * DT)
    assert np.max(np.abs(moved[0])) > 0.1


def test_a_loop_period_other_than_the_plants_integrates_over_its_own(sda10f):
    """``advance`` over a ``dt`` that is not the plant's: the velocity is the plant's
    period's, the configuration Pinocchio's integration of it over the ``dt`` given."""
    compiled, reference = plants(sda10f, PlantSettings())
    q, dt = sda10f.q_home.copy(), 2.5 * DT
    for qd in commands(sda10f.model.nv, 20, 0.5):
        moved, reached = compiled.advance(qd, q, [], dt)
        assert np.array_equal(moved, reference.actuate(qd, q, []))
        assert np.array_equal(reached, pin.integrate(sda10f.model, q, moved * dt))
        assert not np.array_equal(reached, pin.integrate(sda10f.model, q, moved * DT))
        q = reached
