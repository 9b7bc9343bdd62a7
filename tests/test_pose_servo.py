"""The pose servo (teleop/loop/pose_servo.py, docs/design.md 5.1): its filter, twists and
caps against the formulas written here with homogeneous matrices and pinocchio's
log6/exp6, its hold, its state handed to and from the compiled tick, and bad input."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controllers.cjm import _step  # noqa: F401  (an ImportError here fails the suite: no skip)
from teleop.controller_specs import make_controller
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, PoseServo, TeleopLoop

EPS = np.finfo(float).eps


def twist_tolerance(config: LoopConfig, translation: float) -> float:
    """A twist entry's rounding, the servo's against the reference's (other products, the
    same ``log6``): a few ulps of a pose of size ``1 + |t|``, times ``K_p`` for the pose
    gain and ``1/dt`` for the feed-forward's ``log6`` of two nearby targets."""
    return 16 * EPS * (config.kp + config.feed_forward / config.dt) * (1.0 + translation)


def relative(a: pin.SE3, b: pin.SE3) -> pin.SE3:
    """``a^-1 b`` from the homogeneous matrices."""
    return pin.SE3(np.linalg.inv(a.homogeneous) @ b.homogeneous)


def reference_twist(config: LoopConfig, ee: pin.SE3, target: pin.SE3,
                    previous: pin.SE3 | None) -> tuple[np.ndarray, float]:
    """``K_p log6(T_e^-1 T*) + Ad_(T_e^-1 T*) log6(T*_prev^-1 T*)/dt`` and the caps'
    factor ``min(1, v_max/|v|, w_max/|w|)`` (docs/design.md 5.1)."""
    error = relative(ee, target)
    twist = config.kp * pin.log6(error).vector
    if config.feed_forward and previous is not None:
        twist = twist + error.toActionMatrix() @ (pin.log6(relative(previous, target)).vector
                                                  / config.dt)
    scale = min(1.0, config.max_linear_speed / max(np.linalg.norm(twist[:3]), 1e-300),
                config.max_angular_speed / max(np.linalg.norm(twist[3:]), 1e-300))
    return twist, scale


def pose(values: list[float]) -> pin.SE3:
    return pin.exp6(np.array(values))


poses = st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6).map(pose)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ee_count=st.integers(1, 2), data=st.data(),
       tau=st.sampled_from([0.0, 0.001, 0.01, 0.2]), rate=st.sampled_from([100.0, 1000.0]),
       kp=st.floats(0.5, 100.0), max_linear=st.floats(0.01, 2.0),
       max_angular=st.floats(0.05, 5.0), feed_forward=st.booleans())
def test_the_servo_against_the_formulas(ee_count, data, tau, rate, kp, max_linear, max_angular,
                                        feed_forward) -> None:
    """Four periods towards random targets with the EEs at random placements: the filtered
    targets, the twists after the caps and whether a cap scaled one, as the reference."""
    config = LoopConfig(rate=rate, kp=kp, max_linear_speed=max_linear,
                        max_angular_speed=max_angular, target_time_constant=tau,
                        feed_forward=feed_forward)
    servo = PoseServo(config, ee_count)
    alpha = 1.0 - math.exp(-config.dt / tau) if tau > 0.0 else None
    filtered: list[pin.SE3] | None = None
    for _ in range(4):
        targets = data.draw(st.lists(poses, min_size=ee_count, max_size=ee_count))
        placements = data.draw(st.lists(poses, min_size=ee_count, max_size=ee_count))
        previous = filtered
        filtered = (list(targets) if filtered is None or alpha is None
                    else [f * pin.exp6(alpha * pin.log6(relative(f, t)).vector)
                          for f, t in zip(filtered, targets)])
        period = servo.period(targets, placements)
        assert period.previous is None if previous is None else len(period.previous) == ee_count
        scaled = False
        for i in range(ee_count):
            np.testing.assert_allclose(period.targets[i].homogeneous, filtered[i].homogeneous,
                                       rtol=0.0, atol=1e-14)
            twist, scale = reference_twist(config, placements[i], filtered[i],
                                           None if previous is None else previous[i])
            tolerance = twist_tolerance(config, 1.0)
            np.testing.assert_allclose(period.twists[i], twist * scale, rtol=0.0,
                                       atol=tolerance * max(1.0, scale))
            scaled |= scale < 1.0 - 4 * EPS
            assert scale <= 1.0 + 4 * EPS or not period.saturated
        if scaled:
            assert period.saturated
        assert servo.previous is period.targets  # the next period's feed-forward


def test_hold_sets_the_filter_and_keeps_the_earlier_periods() -> None:
    """hold(ee, pose): that EE's filtered and previous targets at pose, the next period's
    twist ``K_p log6(T_e^-1 pose)`` once the filter steps from there; the lists returned
    before are not changed."""
    config = LoopConfig(target_time_constant=0.05)
    servo = PoseServo(config, 2)
    targets = [pose([0.1, 0.0, 0.0, 0.0, 0.0, 0.1]), pose([0.0, 0.2, 0.0, 0.1, 0.0, 0.0])]
    placements = [pin.SE3.Identity(), pin.SE3.Identity()]
    first = servo.period(targets, placements)
    kept = [target.copy() for target in first.targets]
    held = pose([0.0, 0.0, 0.05, 0.0, 0.2, 0.0])
    servo.hold(1, held)
    assert all(a.isApprox(b, 0.0) for a, b in zip(first.targets, kept))
    assert servo.filtered[1] == held and servo.previous[1] == held
    assert servo.filtered[0].isApprox(first.targets[0], 0.0)
    second = servo.period([targets[0], held], placements)
    assert second.targets[1].isApprox(held, 1e-15)
    twist, scale = reference_twist(config, placements[1], held, held)
    np.testing.assert_allclose(second.twists[1], twist * scale, rtol=0.0,
                               atol=twist_tolerance(config, 1.0))


def test_a_hold_while_ticking_compiled_is_the_python_paths() -> None:
    """A hold while the state lives in the compiled tick reaches it: the loops on the
    compiled tick and on the Python path command alike after it, and report the same
    previous targets."""
    plan = load_scenario("paper-hole")
    config = LoopConfig(target_time_constant=0.05)
    loops = []
    for compiled in (True, False):
        controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=config.dt,
                                     time_budget=None)
        loops.append(TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                                compiled_tick=compiled))
    home = loops[0].ee_placement()
    moved = pin.SE3(home.rotation, home.translation + np.array([0.0, 0.01, 0.0]))
    for k in range(40):
        if k == 20:
            for loop in loops:
                loop.hold(0, home)
            assert loops[0].servo.previous[0] == home == loops[1].servo.previous[0]
        steps = [loop.advance(moved) for loop in loops]
        assert type(steps[0]).__name__ == "CompiledPendingStep"
        np.testing.assert_allclose(steps[0].qd, steps[1].qd, rtol=0.0,
                                   atol=1.6e-10 * (1 + np.abs(steps[1].qd).max()))
    assert loops[0].previous_targets[0].isApprox(loops[1].previous_targets[0], 1e-12)


def test_bad_input_is_a_value_error() -> None:
    config = LoopConfig()
    with pytest.raises(ValueError, match="config must be a LoopConfig"):
        PoseServo({"kp": 1.0}, 1)  # type: ignore[arg-type]
    for count in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="ee_count must be a positive integer"):
            PoseServo(config, count)  # type: ignore[arg-type]
    servo = PoseServo(config, 2)
    one = [pin.SE3.Identity()]
    with pytest.raises(ValueError, match="expected 2 target poses, got 1"):
        servo.period(one, one * 2)
    with pytest.raises(ValueError, match="expected 2 EE placements, got 1"):
        servo.period(one * 2, one)
    with pytest.raises(ValueError, match="expected 2 EE placements and targets, got 1 and 2"):
        servo.twists(one, one * 2, None)
    with pytest.raises(ValueError, match="no kernel"):
        servo.run_kernel(one * 2, np.zeros(6), True)
    assert servo.filtered is None and servo.previous is None  # nothing ran


def test_the_servo_alone_hands_the_state_to_and_from_the_kernel() -> None:
    """No module but the servo calls the kernel's ``history()`` or ``set_history``: the
    filter's state has one keeper (docs/design.md 5.1)."""
    root = Path(__file__).resolve().parent.parent
    callers = set()
    for package in ("constraints", "controllers", "teleop", "web"):
        for path in (root / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                        and (node.func.attr == "set_history"
                             or node.func.attr == "history" and not node.args)):
                    callers.add(path.relative_to(root).as_posix())
    # the compiled tick's own set_history hands the flags on to the C++ Tick
    assert callers == {"teleop/loop/pose_servo.py", "controllers/cjm/compiled_tick.py"}


def test_a_hold_of_no_such_ee_is_a_value_error() -> None:
    """hold(ee, pose) with ``ee`` outside ``range(ee_count)`` (-1 included, which the
    supervisor's list would take as the last EE) is a ValueError and changes nothing: it
    held no EE at all, silently, while the loop's supervisor held another."""
    servo = PoseServo(LoopConfig(target_time_constant=0.05), 2)
    targets = [pin.SE3.Identity(), pin.SE3.Identity()]
    first = servo.period(targets, targets)
    held = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.05]))
    for ee in (2, -1, 1.0, True, np.int64(2)):
        with pytest.raises(ValueError, match="ee must be an EE index in range\\(2\\)"):
            servo.hold(ee, held)  # type: ignore[arg-type]
    assert servo.filtered is first.targets and servo.previous is first.targets
    servo.hold(np.int64(1), held)  # an index numpy gives is an index
    assert servo.filtered[1] == held and servo.previous[1] == held


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled tick", "python path"])
def test_a_target_that_is_not_finite_fails_its_period_and_the_servo_starts_over(compiled):
    """One NaN target: that period is ``failed`` with a finite command; the filter does not
    keep it, so the next finite target's period is a first one (the target itself, no
    feed-forward: the law written in this file), and the periods after it are not failed
    (review: a NaN target used to poison the filter until reset())."""
    plan = load_scenario("paper-hole")
    config = LoopConfig(target_time_constant=0.05)
    controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=config.dt,
                                 time_budget=None)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config, compiled_tick=compiled)
    home = loop.ee_placement()
    moved = pin.SE3(home.rotation, home.translation + np.array([0.0, 0.005, 0.0]))
    for _ in range(10):
        assert loop.advance(moved).status != "failed"
    refused = loop.advance(pin.SE3(home.rotation, np.array([np.nan, 0.0, 0.0])))
    assert refused.status == "failed" and np.all(np.isfinite(refused.qd))
    ee = loop.ee_placement()
    after = loop.advance(moved)
    assert after.status != "failed"
    assert after.targets[0].isApprox(moved, 1e-14) and after.previous_targets is None
    twist, scale = reference_twist(config, ee, moved, None)
    np.testing.assert_allclose(after.twists[0], scale * twist, rtol=0.0,
                               atol=twist_tolerance(config, 1.0))
    for _ in range(20):
        step = loop.advance(moved)
        assert step.status != "failed" and np.all(np.isfinite(step.qd))
