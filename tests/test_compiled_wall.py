"""The ports' walls applied inside ``mj_step`` by the compiled callback
(``teleop/plants/port_wall.c``, docs/design.md section 17.5) give the forces and the motion
the Python walls give (each physics step split, ``PortWall`` applied by ``mj_applyFT``;
tests/test_mujoco_plant.py holds those to Pinocchio's ``J_P^T F``).

The two paths apply the same force (the same arithmetic, to the last bits of a 3-term
dot product) into two different vectors MuJoCo sums (``qfrc_passive`` against
``qfrc_applied``), so the runs agree to rounding: 1e-12 relative to the largest force and
to 1e-12 rad in the joints over hundreds of periods of stable servoed dynamics. The
compiler is there wherever the suite runs (the extension needs one): these tests do not
skip.
"""

from __future__ import annotations

import threading

import numpy as np
import pinocchio as pin

from constraints import Hole
from teleop.plants import MujocoPlant
from teleop.plants.compiled_wall import wall_library

DT = 1e-3


def commands(nv: int, periods: int) -> list[np.ndarray]:
    """A smooth joint-velocity command sweeping every joint (rad/s)."""
    phases = np.arange(nv)
    return [0.2 * np.sin(2.0 * np.pi * (k * DT) * (1.0 + 0.3 * phases) + phases)
            for k in range(periods)]


def record(plant: MujocoPlant, robot, holes, periods: int) -> dict[str, np.ndarray]:
    """The run's measures per period: the ports' forces, spring parts, displacements, the
    simulated joints."""
    q = robot.q_home.copy()
    out: dict[str, list[np.ndarray]] = {"force": [], "spring": [], "displacement": [], "qpos": []}
    for qd in commands(robot.model.nv, periods):
        q = pin.integrate(robot.model, q, plant.actuate(qd, q, holes) * DT)
        measures = plant.measures()
        out["force"].append(measures.port_forces.copy())
        out["spring"].append(measures.port_spring_forces.copy())
        out["displacement"].append(measures.port_displacements.copy())
        out["qpos"].append(plant.mj_data.qpos.copy())
    return {name: np.array(values) for name, values in out.items()}


def assert_same_run(compiled: dict[str, np.ndarray], python: dict[str, np.ndarray]) -> None:
    scale = max(1.0, float(np.max(np.abs(python["force"]))))
    for name in ("force", "spring"):
        np.testing.assert_allclose(compiled[name], python[name], rtol=0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(compiled["displacement"], python["displacement"], rtol=0.0,
                               atol=1e-15)
    np.testing.assert_allclose(compiled["qpos"], python["qpos"], rtol=0.0, atol=1e-12)


def moving_hole(robot, link: str | None = None) -> Hole:
    """A hole on ``link`` 8 cm along it, 1 mm off the axis and moving at 5 mm/s, with a
    stiffer wall and more damping than the defaults (every term of the force acts)."""
    hole = Hole.on_link(robot, robot.q_home, distance=0.08, **({"link": link} if link else {}))
    hole.move_to(hole.center + np.array([0.0, 1e-3, 0.0]), velocity=np.array([0.0, 5e-3, 0.0]))
    hole.tissue_stiffness = 3000.0
    hole.tissue_damping = 25.0
    return hole


def test_the_compiled_wall_is_built_here():
    assert wall_library() is not None


def test_one_moving_hole_gives_the_python_walls_forces_and_motion(sda10f):
    hole = moving_hole(sda10f)
    compiled = MujocoPlant(sda10f, DT)
    assert compiled._compiled_walls is not None
    python = MujocoPlant(sda10f, DT, compiled_walls=False)
    runs = [record(plant, sda10f, [hole], 400) for plant in (compiled, python)]
    assert np.max(np.abs(runs[1]["force"])) > 1.0  # the wall pushes (N)
    assert np.max(np.abs(runs[1]["force"] - runs[1]["spring"])) > 0.05  # and damps
    assert_same_run(*runs)


def test_two_holes_on_the_dual_robot(dual):
    holes = [moving_hole(dual, link) for link in dual.constrained_links]
    runs = [record(MujocoPlant(dual, DT, compiled_walls=flag), dual, holes, 200)
            for flag in (True, False)]
    assert runs[0]["force"].shape[1] == 2
    assert_same_run(*runs)


def test_a_plant_without_holes_is_not_touched_by_another_ones_walls(sda10f):
    """The callback is the process's: a plant stepping between another's periods, without
    holes, runs as one alone."""
    hole = moving_hole(sda10f)
    with_holes = MujocoPlant(sda10f, DT)
    alone = record(MujocoPlant(sda10f, DT), sda10f, [], 100)
    bare = MujocoPlant(sda10f, DT)
    q = sda10f.q_home.copy()
    q_bare = sda10f.q_home.copy()
    qpos = []
    for qd in commands(sda10f.model.nv, 100):
        q = pin.integrate(sda10f.model, q, with_holes.actuate(qd, q, [hole]) * DT)
        q_bare = pin.integrate(sda10f.model, q_bare, bare.actuate(qd, q_bare, []) * DT)
        qpos.append(bare.mj_data.qpos.copy())
    np.testing.assert_array_equal(np.array(qpos), alone["qpos"])
    assert np.max(np.abs(with_holes.measures().port_forces)) > 0.0


def test_plants_in_threads_each_get_their_own_walls(sda10f):
    """Two plants with different holes stepping at once in two threads (the web UI runs a
    loop per robot) give each its own run."""
    holes = [moving_hole(sda10f), moving_hole(sda10f)]
    holes[1].tissue_stiffness = 500.0
    expected = [record(MujocoPlant(sda10f, DT), sda10f, [hole], 200) for hole in holes]
    results: list[dict[str, np.ndarray]] = [{}, {}]

    def run(i: int) -> None:
        results[i] = record(MujocoPlant(sda10f, DT), sda10f, [holes[i]], 200)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for result, reference in zip(results, expected):
        for name in reference:
            np.testing.assert_array_equal(result[name], reference[name])
