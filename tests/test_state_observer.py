"""The joint-state observer (docs/design.md 5.6) against references written here: the
gain against a scalar Kalman filter's covariance recursion run to convergence, the
estimate's error variance against the closed form of a first-order filter, and a Kalman
filter with its own time-varying gain run beside it on the same draws."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, strategies as st

from teleop import load_robot
from teleop.loop import LoopConfig, TeleopLoop
from teleop.loop.state_observer import (
    DEFAULT_VELOCITY_NOISE,
    StateObserver,
    StateObserverConfig,
    estimate_variance,
    kalman_gain,
)
from teleop.plants.imperfect import Imperfections


def riccati_gain(encoder_noise: float, velocity_noise: float, dt: float) -> float:
    """The scalar Kalman filter's gain after its covariance recursion converged, from a
    prior of the measurement's own variance (the reference)."""
    process, measurement = (velocity_noise * dt) ** 2, encoder_noise ** 2
    posterior, gain = measurement, 1.0
    for _ in range(1_000_000):
        prior = posterior + process
        new_gain = prior / (prior + measurement)
        posterior = (1.0 - new_gain) * prior
        if abs(new_gain - gain) <= 1e-13 * new_gain:
            return new_gain
        gain = new_gain
    raise AssertionError("the recursion did not converge")


@given(st.floats(1e-5, 1e-2), st.floats(1e-2, 1.0), st.sampled_from([1e-3, 2e-3, 1e-2]))
def test_the_gain_is_the_converged_kalman_gain(encoder_noise, velocity_noise, dt):
    gain = kalman_gain(encoder_noise, velocity_noise, dt)
    assert 0.0 < gain < 1.0
    assert gain == pytest.approx(riccati_gain(encoder_noise, velocity_noise, dt), rel=1e-9)


def test_the_gain_is_one_without_noise_and_the_measurement_is_passed_on(sda10f):
    assert kalman_gain(0.0, 0.05, 1e-3) == 1.0
    observer = StateObserver(sda10f.model, 1e-3, 0.0, 0.05)
    assert observer.gain == 1.0
    measured = sda10f.q_home + 0.01
    assert observer.estimate(measured, np.ones(sda10f.model.nv)) is measured
    assert observer.estimate(measured, np.ones(sda10f.model.nv)) is measured


def joint_path(model: pin.Model, steps: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """A smooth path's configurations and the velocities that integrate it exactly."""
    rng = np.random.default_rng(11)
    amplitude, frequency = rng.uniform(0.1, 0.5, model.nv), rng.uniform(0.2, 1.0, model.nv)
    velocities = np.array([amplitude * np.cos(2 * np.pi * frequency * k * dt)
                           for k in range(steps)])
    q = [pin.neutral(model)]
    for v in velocities[:-1]:
        q.append(pin.integrate(model, q[-1], v * dt))
    return np.array(q), velocities


@pytest.mark.slow
@pytest.mark.parametrize("name", ["sda10f", "sda10f_dual_mobile"])
def test_the_estimate_variance_is_the_first_order_filters(name):
    """Encoder noise alone (the command exact), 40,000 periods: at the fixed gain, the
    estimate's error variance per joint within 15 % of ``L sigma^2 / (2 - L)`` (about
    1,000 independent samples at L = 0.05: a 4.5 % standard error); the observer with
    its own Kalman gain equal, every period, to within 1e-12 rad of a Kalman filter
    written here (its time-varying gain from the first measurement)."""
    model = load_robot(name).model
    dt, sigma, velocity_noise = 1e-3, 1e-3, 0.05
    gain = kalman_gain(sigma, velocity_noise, dt)
    observer = StateObserver(model, dt, gain=gain)
    kalman = StateObserver(model, dt, sigma, velocity_noise)
    assert kalman.gain == gain
    steps = 40_000
    true_q, velocities = joint_path(model, steps, dt)
    rng = np.random.default_rng(5)
    errors = []
    reference, posterior = None, sigma ** 2
    for k in range(steps):
        measured = pin.integrate(model, true_q[k], rng.normal(0.0, sigma, model.nv))
        command = velocities[k - 1] if k else np.zeros(model.nv)
        estimate = observer.estimate(measured, command)
        filtered = kalman.estimate(measured, command)
        if reference is None:
            reference = measured
        else:
            prior = posterior + (velocity_noise * dt) ** 2
            k_gain = prior / (prior + sigma ** 2)
            posterior = (1.0 - k_gain) * prior
            predicted = pin.integrate(model, reference, command * dt)
            reference = pin.integrate(model, predicted,
                                      k_gain * pin.difference(model, predicted, measured))
        np.testing.assert_allclose(pin.difference(model, reference, filtered), 0.0, atol=1e-12)
        errors.append(pin.difference(model, true_q[k], estimate))
    variance = np.var(np.array(errors)[1000:], axis=0)
    np.testing.assert_allclose(variance, estimate_variance(gain, sigma), rtol=0.15)
    assert estimate_variance(gain, sigma) < 0.03 * sigma ** 2


#: a whole-body robot with a planar base (nq 15, nv 14): the heading in the tangent space
MOBILE = load_robot("sda10f_dual_mobile").model


@given(st.floats(0.01, 1.0), st.lists(st.floats(-2.0, 2.0), min_size=MOBILE.nv,
                                      max_size=MOBILE.nv))
def test_an_exact_command_without_noise_keeps_the_estimate_on_the_robot(gain, velocity):
    """No noise, the command what the joints do: the estimate is the robot's
    configuration to round-off, whatever the gain."""
    model = MOBILE
    observer = StateObserver(model, 1e-3, gain=gain)
    q = pin.neutral(model)
    observer.estimate(q, np.zeros(model.nv))
    for _ in range(50):
        q = pin.integrate(model, q, np.array(velocity) * 1e-3)
        estimate = observer.estimate(q, np.array(velocity))
    np.testing.assert_allclose(estimate, q, atol=1e-12)


def test_a_non_finite_measurement_is_passed_on_and_restarts_the_observer(sda10f):
    model = sda10f.model
    observer = StateObserver(model, 1e-3, gain=0.1)
    observer.estimate(sda10f.q_home, np.zeros(model.nv))
    bad = np.full(model.nq, np.nan)
    assert observer.estimate(bad, np.zeros(model.nv)) is bad
    fresh = sda10f.q_home + 0.01
    assert observer.estimate(fresh, np.zeros(model.nv)) is fresh


@pytest.mark.parametrize("kwargs, message", [
    ({"gain": 0.0}, r"^gain must be > 0"),
    ({"gain": 1.5}, r"^gain must be <= 1, got 1.5"),
    ({"gain": math.nan}, r"^gain must be"),
    ({"encoder_noise": -1e-3}, r"^encoder_noise must be >= 0"),
    ({"velocity_noise": 0.0}, r"^velocity_noise must be > 0"),
    ({"velocity_noise": math.inf}, r"^velocity_noise must be"),
    ({"enabled": "yes"}, r"^enabled must be True or False"),
])
def test_bad_settings_are_refused_by_name(kwargs, message):
    with pytest.raises(ValueError, match=message):
        StateObserverConfig(**kwargs)


def test_the_loop_takes_the_plants_declared_noise_or_the_set_gain(ur5_instrument):
    from controllers.cjm import CJMController

    robot = ur5_instrument
    noisy = Imperfections(encoder_noise=1e-3, seed=1).plant(robot.model, 1e-3)
    quiet = Imperfections(latency=1).plant(robot.model, 1e-3)
    assert TeleopLoop(robot, CJMController(robot, []), plant=noisy).observer.gain == \
        kalman_gain(1e-3, DEFAULT_VELOCITY_NOISE, 1e-3)
    assert TeleopLoop(robot, CJMController(robot, []), plant=quiet).observer.gain == 1.0
    off = LoopConfig(state_observer=StateObserverConfig(enabled=False))
    assert TeleopLoop(robot, CJMController(robot, []), plant=noisy, config=off).observer.gain == 1.0
    fixed = LoopConfig(state_observer=StateObserverConfig(gain=0.2))
    assert TeleopLoop(robot, CJMController(robot, []), plant=noisy,
                      config=fixed).observer.gain == 0.2
    with pytest.raises(ValueError, match="^state_observer must be a StateObserverConfig"):
        LoopConfig(state_observer=0.2)  # type: ignore[arg-type]


def run_compare(tmp_path, *options: str) -> subprocess.CompletedProcess:
    """``teleop compare`` of a short noisy ``paper-hole`` (the CJM, kinematic plant)."""
    return subprocess.run(
        [sys.executable, "-m", "teleop.cli", "compare", "--scenario", "paper-hole",
         "--controllers", "cjm", "--duration", "0.3", "--encoder-noise", "1e-3", "--no-plots",
         "--quiet", "--out", str(tmp_path), *options],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": os.getcwd()})


@pytest.mark.slow
def test_the_command_line_chooses_the_observer(tmp_path):
    """``--state-filter off`` takes the encoders raw: a larger hole error than the
    default Kalman observer on the same noise draw; a bad value is refused by name."""
    errors = {}
    for mode in ("kalman", "off", "0.5"):
        run = run_compare(tmp_path / mode, "--state-filter", mode)
        assert run.returncode == 0, run.stderr
        metrics = json.loads((tmp_path / mode / "metrics.json").read_text())
        errors[mode] = metrics["controllers"]["cjm"]["constraint_error_max_m"]
    assert errors["kalman"] < errors["0.5"] < errors["off"]
    bad = run_compare(tmp_path / "bad", "--state-filter", "2")
    assert bad.returncode == 2
    assert "--state-filter: expected kalman, off or a gain in (0, 1], got '2'" in bad.stderr
