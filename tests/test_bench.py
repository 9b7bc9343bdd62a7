"""``teleop bench``: its constraint problems placed as documented (against Pinocchio), the
barrier held in some steps only, the C++ floor running the same step as ``solve``, the
allocation counter against known allocations, the targets' ratios from the rows, and the
command line. No wall-clock assertion: timing is the bench's own output."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController
from teleop import load_robot
from teleop.experiments.allocations import count_allocations, counter_library
from teleop.experiments.bench import (StepTiming, bench_named, format_table, format_targets,
                                      run_bench, target_checks)
from teleop.experiments.bench_problems import (BARRIER_OFFSET, BENCH_TWIST,
                                               DEFAULT_HOLE_DISTANCE, bench_configurations,
                                               bench_problem_named, bench_twist)

ROBOT = "sda10f"


def link_point_at_home(robot, link: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The world point ``DEFAULT_HOLE_DISTANCE`` along ``link``'s axis at home, the axis
    (world), and that point's world velocity under the least-norm ``qd`` giving the
    bench's twist (Pinocchio's frame velocity of a frame placed at the point)."""
    model = robot.model.copy()
    frame = model.getFrameId(link)
    axis = np.asarray(robot.link_axes[link])
    offset = pin.SE3(np.eye(3), DEFAULT_HOLE_DISTANCE[ROBOT] * axis)
    point_frame = model.addFrame(pin.Frame("bench_point", model.frames[frame].parentJoint,
                                           model.frames[frame].placement * offset,
                                           pin.FrameType.OP_FRAME))
    data = model.createData()
    pin.computeJointJacobians(model, data, robot.q_home)
    pin.updateFramePlacements(model, data)
    ee = pin.getFrameJacobian(model, data, robot.ee_frame_ids[0], pin.LOCAL)
    qd = np.linalg.pinv(ee) @ np.array(BENCH_TWIST)
    velocity = pin.getFrameJacobian(model, data, point_frame, pin.LOCAL_WORLD_ALIGNED)[:3] @ qd
    return data.oMf[point_frame].translation, data.oMf[frame].rotation @ axis, velocity


def test_each_constraint_problem_is_placed_on_the_link_point():
    robot = load_robot(ROBOT)
    link = robot.constrained_links[0]
    point, axis, velocity = link_point_at_home(robot, link)
    across = velocity - (velocity @ axis) * axis
    assert np.linalg.norm(across) > 1e-4  # the twist moves the point across the link

    (plane,) = bench_problem_named("sda10f/plane").constraints
    assert type(plane) is Plane and plane.link == link
    np.testing.assert_allclose(plane.normal, across / np.linalg.norm(across), atol=1e-12)
    assert abs(plane.normal @ (point - plane.plane_point)) < 1e-12  # through the point

    (barrier,) = bench_problem_named("sda10f/barrier").constraints
    assert type(barrier) is Barrier and barrier.link == link
    np.testing.assert_allclose(barrier.normal, -plane.normal, atol=1e-12)  # against the motion
    assert barrier.normal @ (point - barrier.plane_point) == pytest.approx(BARRIER_OFFSET,
                                                                           abs=1e-12)

    (lock,) = bench_problem_named("sda10f/lock").constraints
    assert type(lock) is PointLock and lock.link == link
    np.testing.assert_allclose(lock.target, point, atol=1e-12)

    (hole,) = bench_problem_named(ROBOT).constraints
    assert type(hole) is Hole
    np.testing.assert_allclose(hole.center, point, atol=1e-12)


def test_the_barrier_is_held_exactly_where_the_free_command_would_cross_it():
    """The CJM holds the barrier in the steps where the command without it, from the
    same controller with no constraint, breaks its row ``A qd >= b`` (section 12); the
    bench's configurations give some of each."""
    problem = bench_problem_named("sda10f/barrier")
    robot, (barrier,) = problem.robot, problem.constraints
    iterations = 200
    (timing,) = bench_named(problem.label, ["cjm"], iterations, 5)
    assert 0 < timing.active_barrier_steps < iterations

    configurations = bench_configurations(robot, [barrier], iterations, base=problem.base)
    twist = bench_twist(robot, [barrier], problem.base)
    free = CJMController(robot, [], acceleration_limit=None)
    model, data = robot.model, robot.model.createData()
    crossing = 0
    for q in configurations:
        qd = free.solve(q, twist)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        rows, bound = barrier.rows(model, data, model.getFrameId(barrier.link))
        crossing += bool(rows @ qd < bound - 1e-12)
    assert crossing == timing.active_barrier_steps


@pytest.fixture(scope="module")
def compiled_hole():
    robot = load_robot(ROBOT)
    problem = bench_problem_named(ROBOT)
    controller = CJMController(robot, list(problem.constraints), acceleration_limit=None,
                               backend="compiled")
    return robot, problem, controller


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(1, 40),
       scale=st.floats(1e-3, 10.0))
def test_the_floor_runs_the_step_solve_runs(compiled_hole, seed, count, scale):
    """``CompiledStep.time_steps`` runs the one-call step over every configuration: the
    C++ state after it is the last configuration's, and the next ``solve`` answers as
    it did before (the floor leaves nothing behind)."""
    robot, problem, controller = compiled_hole
    configurations = bench_configurations(robot, problem.constraints, count, seed=seed)
    twists = scale * np.tile(bench_twist(robot, problem.constraints), (count, 1))
    before = controller.solve(configurations[0], twists[0]).copy()
    nanoseconds = controller.step.time_steps(configurations, twists)
    assert nanoseconds.shape == (count,) and np.all(nanoseconds > 0)
    np.testing.assert_array_equal(controller.step.pipeline.q, configurations[-1])
    np.testing.assert_array_equal(controller.solve(configurations[0], twists[0]), before)


def test_the_floor_refuses_what_does_not_fit(compiled_hole):
    robot, problem, controller = compiled_hole
    configurations = bench_configurations(robot, problem.constraints, 3)
    twists = np.tile(bench_twist(robot, problem.constraints), (3, 1))
    with pytest.raises(ValueError, match="one q"):
        controller.step.time_steps(configurations[:, :-1], twists)
    with pytest.raises(ValueError, match="one q"):
        controller.step.time_steps(configurations, twists[:2])
    configurations[1, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        controller.step.time_steps(configurations, twists)


def test_the_python_step_has_no_floor():
    robot = load_robot(ROBOT)
    problem = bench_problem_named(ROBOT)
    controller = CJMController(robot, list(problem.constraints), backend="python")
    assert not hasattr(controller.step, "time_steps")
    (timing,) = bench_named(ROBOT, ["cjm:python"], 10, 1)
    assert timing.floor_median_us is None and timing.called_over_floor is None


@pytest.fixture(scope="module")
def library():
    built = counter_library()
    assert built is not None, "no C compiler here: the allocation counter needs one"
    return built


def test_the_counter_counts_known_allocations(library):
    """With the shim preloaded, ``n`` calls of ``malloc`` (the process's, as any library
    calls it) through ctypes count ``n`` more than none (what ctypes itself allocates is
    the same for both)."""
    script = f"""
import ctypes, sys
sys.path.insert(0, {os.getcwd()!r})
from teleop.experiments.allocations import allocation_counter
count = allocation_counter({library!r})
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
def allocations(n):
    before = count()
    for _ in range(n):
        libc.free(libc.malloc(64))
    return count() - before
allocations(100)
print(allocations(1000) - allocations(0), allocations(2000) - allocations(1000))
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "LD_PRELOAD": library}, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["1000", "1000"]


def test_the_compiled_hole_step_allocates_only_its_command(library):
    """Docs/design.md section 16: nothing in the step allocates but the returned array;
    its C++ loop allocates nothing, the Python-called step at least the command."""
    counted = count_allocations(ROBOT, ["cjm", "qp:daqp"], 50, library)
    assert counted["cjm"].floor == 0.0
    assert counted["cjm"].called >= 1.0
    assert counted["qp:daqp"].floor is None and counted["qp:daqp"].called > counted["cjm"].called


def test_without_a_compiler_the_bench_runs_and_says_n_a(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert counter_library([str(tmp_path / "no-such-cc")]) is None
    timings = bench_named(ROBOT, ["cjm", "qp:daqp"], 10, 1, library=None)
    assert all(t.called_allocations is None and t.floor_allocations is None for t in timings)
    rows = format_table(timings).splitlines()[1:3]
    assert all(" n/a " in row for row in rows)


def timing(problem: str, controller: str, median: float, p99: float,
           floor: float | None = None) -> StepTiming:
    return StepTiming(robot=problem, controller=controller, dof=8, constraint_rows=2,
                      median_us=median, p99_us=p99, max_us=p99, iterations=10,
                      max_constraint_residual=0.0, method="", status_counts={},
                      floor_median_us=floor)


def test_the_targets_are_the_ratios_of_the_rows():
    rows = [timing("sda10f", "cjm", 4.0, 8.0, floor=2.5), timing("sda10f", "qp:daqp", 200.0, 300.0),
            timing("sda10f", "mink:daqp", 90.0, 100.0),
            timing("sda10f/plane", "cjm", 7.0, 30.0),
            timing("sda10f/plane", "mink:daqp", 210.0, 300.0),
            timing("chain64", "cjm", 21.0, 30.0), timing("chain64", "cjm:python", 400.0, 500.0)]
    checks = {(c.problem, c.controller, c.measure): c for c in target_checks(rows)}
    assert checks[("sda10f", "cjm", "x qp:daqp")].value == 200.0 / 4.0
    assert checks[("sda10f", "cjm", "x mink:daqp")].value == 90.0 / 4.0
    assert not checks[("sda10f", "cjm", "x mink:daqp")].met  # 22.5 < 25
    assert checks[("sda10f", "cjm", "called / C++ floor")].value == 4.0 / 2.5
    assert checks[("sda10f/plane", "cjm", "median / sda10f hole")].value == 7.0 / 4.0
    assert checks[("sda10f/plane", "cjm", "p99 / median")].value == 30.0 / 7.0
    assert not checks[("sda10f/plane", "cjm", "p99 / median")].met
    assert checks[("sda10f/plane", "cjm", "x mink:daqp")].value == 30.0
    assert checks[("chain64", "cjm", "median / sda10f hole")].value == 21.0 / 4.0
    # the Python reference is not held to them; a row without a floor has no such ratio
    assert not any(c.controller == "cjm:python" for c in checks.values())
    assert ("sda10f/plane", "cjm", "called / C++ floor") not in checks
    (plane,) = [line for line in format_targets(list(checks.values()))
                if line.startswith("sda10f/plane ")]
    assert plane.split()[1:] == ["cjm", "1.75*", "4.29*", "30.00"]  # no qp:daqp row, no floor


def test_the_command_line_writes_the_rows_ratios_and_targets(tmp_path):
    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, "-m", "teleop.cli", "bench", "--quick", "--no-scaling",
                          "--robots", "sda10f,sda10f/plane,sda10f/lock,sda10f/barrier",
                          "--controllers", "cjm,qp:daqp,mink:daqp", "--json", str(out)],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert "targets (docs/design.md section 16, the bench)" in run.stdout
    assert "sda10f/barrier cjm: the barrier held in" in run.stdout
    rows = json.loads(out.read_text())
    assert [r["robot"] for r in rows[::3]] == ["sda10f", "sda10f/plane", "sda10f/lock",
                                               "sda10f/barrier"]
    hole = rows[0]["median_us"]
    hole_medians = {r["controller"]: r["median_us"] for r in rows if r["robot"] == "sda10f"}
    for row in rows:
        assert row["p99_over_median"] == pytest.approx(row["p99_us"] / row["median_us"])
        assert row["median_over_sda10f_hole"] == pytest.approx(
            row["median_us"] / hole_medians[row["controller"]])
        assert row["called_allocations"] is not None  # gcc is here
        for check in row["targets"]:
            assert check["met"] == (check["value"] >= check["limit"] if check["at_least"]
                                    else check["value"] <= check["limit"])
    plane = next(r for r in rows if r["robot"] == "sda10f/plane" and r["controller"] == "cjm")
    assert {c["measure"] for c in plane["targets"]} >= {"median / sda10f hole", "p99 / median",
                                                        "x mink:daqp", "x qp:daqp"}
    assert plane["median_over_sda10f_hole"] == pytest.approx(plane["median_us"] / hole)


def test_an_unknown_problem_is_refused_before_any_run():
    with pytest.raises(ValueError, match=r"^unknown robot 'sda10f/nope'.*sda10f/plane"):
        run_bench(["sda10f/nope"])


def test_the_loop_bench_times_every_period_of_both_paths():
    """``teleop bench``'s loop section: each path runs every period of the scenario; the
    loop time is the sum of the ticks, each tick costs at least the step it contains (the
    compiled tick's ``step_time_us``, timed in C++), the targets scale with the step."""
    from teleop.experiments.bench_loop import format_loop_table, scenario_loop, time_loop

    compiled, python = (time_loop("paper-hole", flag, duration=0.2) for flag in (True, False))
    assert compiled.ticks == python.ticks == 200
    loop, targets = scenario_loop("paper-hole", True, 0.05)
    pending = [loop.advance(target) for target in targets]
    assert loop.compiled is not None and len(pending) == 50
    assert all(p.tick_time_us >= p.step_time_us > 0.0 for p in pending)
    table = format_loop_table([compiled, python], step_us=4.5)
    assert f"{0.15 * 0.2 / 10:>9.3f}" in table.splitlines()[2]  # the target, scaled by 1x
    for timing in (compiled, python):  # a sum over the ticks: half of them >= the median
        assert timing.loop_time_s >= timing.ticks / 2 * timing.tick_median_us * 1e-6
        assert timing.tick_median_us <= timing.tick_p99_us


def test_the_acceleration_step_line_times_the_compiled_step_with_and_without_limits():
    """``teleop bench``'s issue 32 line: the compiled step alone at every period of the
    scenario, with and without the robot's acceleration limits; the ratio the two
    medians', marked when above the target."""
    from teleop.experiments.bench_loop import (ACCELERATION_COST_TARGET, AccelerationStepCost,
                                               format_acceleration_step_line,
                                               time_acceleration_steps)

    cost = time_acceleration_steps(duration=0.1, repeats=1)
    assert cost is not None  # the compiled step, as the loop's compiled tick above
    assert cost.steps == 100
    assert cost.limited_us > 0.0 and cost.without_us > 0.0
    assert cost.ratio == cost.limited_us / cost.without_us
    assert cost.repeats == 1 and "median of 1 runs' medians" in format_acceleration_step_line(cost)
    above = AccelerationStepCost("fast-lateral", 100, 1.0, 1.0 + ACCELERATION_COST_TARGET)
    assert f"{1.0 + ACCELERATION_COST_TARGET:.2f}x*" in format_acceleration_step_line(above)
    below = AccelerationStepCost("fast-lateral", 100, 1.0, ACCELERATION_COST_TARGET)
    assert f"{ACCELERATION_COST_TARGET:.2f}x (" in format_acceleration_step_line(below)


def test_the_measured_period_line_times_compare_s_periods():
    """``teleop bench``'s compare line: every period timed around ``tick_measured_later``
    (so at least its compiled tick), the target's ratio the period's with its measures
    after the run (marked when missed), the hot path's beside it."""
    from teleop.experiments.bench_loop import (MeasuredPeriod, format_measured_period_line,
                                               time_measured_period)

    period = time_measured_period("paper-hole", duration=0.1)
    assert period.ticks == 100
    assert period.period_median_us >= period.tick_median_us > 0.0
    assert period.period_median_us <= period.period_p99_us
    assert period.ratio == period.period_median_us / period.tick_median_us
    assert period.measures_after_us > 0.0
    assert period.total_ratio == ((period.period_median_us + period.measures_after_us)
                                  / period.tick_median_us)
    line = format_measured_period_line(MeasuredPeriod("paper-hole", 10, 12.0, 40.0, 10.0, 18.0))
    assert "with its measures 30.0 us" in line and "3.00x (target" in line
    assert "(p99 40.0, 1.20x)" in line
    assert "after the run 18.0 us (CPU time, 1000 measured together)" in line
    assert "3.10x* (target" in format_measured_period_line(
        MeasuredPeriod("paper-hole", 10, 12.0, 40.0, 10.0, 19.0))
