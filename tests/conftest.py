"""Shared fixtures: the built-in robots, loaded once, and a hole on each; Hypothesis's
profiles (by default the same examples every run; ``HYPOTHESIS_PROFILE=explore`` draws new
ones, CONTRIBUTING.md)."""

from __future__ import annotations

import os
from fnmatch import fnmatch

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import settings

from teleop import load_robot

# "pinned", the default, locally and in CI: every run draws the same examples (seeded by
# each test's own code), so a run does not depend on its luck. "explore", run on purpose:
# new examples every run, a failing one kept in .hypothesis/ and replayed first next time;
# what it finds becomes an @example on the test, so the default run checks it from then on.
# No deadline in either: an example's wall time is not asserted (a loaded machine took
# 347 ms over the default 200 ms for one example of test_force_filter.py that takes 3 ms).
settings.register_profile("pinned", derandomize=True, database=None, print_blob=True,
                          deadline=None)
settings.register_profile("explore", derandomize=False, print_blob=True, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "pinned"))


def draw_no_project_constants() -> bool:
    """Keep the pinned examples independent of which test files run.

    Hypothesis (6.131 and later) sometimes draws a literal found in the project's modules
    imported so far, so the same test drew other examples alone than with every file
    collected (a fast-tier run could fail where the full run passed). The pool has no
    public switch: its private reader is replaced by an empty pool. False when this
    Hypothesis has no such reader (tests/test_hypothesis_pinned.py then fails, saying so).
    """
    from hypothesis.internal.conjecture import providers

    if not callable(getattr(providers, "_get_local_constants", None)):
        return False
    no_constants = providers.Constants()
    providers._get_local_constants = lambda: no_constants
    return True


#: whether the pinned profile's examples are the same in any selection of test files
PROJECT_CONSTANTS_OFF = (os.environ.get("HYPOTHESIS_PROFILE", "pinned") == "pinned"
                         and draw_no_project_constants())

#: the tiers (CONTRIBUTING.md): the markers each test file's tests carry, by file name
#: (a test may also carry one itself, e.g. ``timing``); a new file that drives the
#: browser, runs MuJoCo, fuzzes or takes more than about 10 s is added here
FILE_MARKERS = {
    "browser": ("test_browser*.py",),
    "physics": ("test_mujoco_*.py", "test_plant_*.py", "test_web_plant.py",
                "test_browser_plant.py", "test_supervisor.py", "test_contact_compare.py"),
    "fuzz": ("*fuzz*.py",),
    "slow": ("test_examples.py", "test_inputs_master.py", "test_whole_body_experiments.py",
             "test_loop.py", "test_sweep.py", "test_python_backend.py", "test_cli.py",
             "test_collision_experiments.py", "test_session_cli.py", "test_web_cli.py",
             "test_experiments.py", "test_sweep_summary.py", "test_results_doc.py",
             "test_bench.py", "test_web_trust.py", "test_scenarios_any_robot.py",
             "test_ros2_wire.py", "test_plant_encoder_noise.py", "test_web_ros2.py",
             "test_web_ros2_safety.py", "test_ros2_master.py", "test_ros2_realtime.py",
             "test_walk_backends.py", "test_variations.py", "test_inputs_authentication.py",
             "test_web_priorities.py", "test_web_ui.py",
             # pytest run in subprocesses, seconds each: the tiers' own checks
             "test_hypothesis_pinned.py", "test_timing_tier.py"),
}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark each test by its file (``FILE_MARKERS``), then leave the ``timing`` tests out
    of any run whose ``-m`` does not name ``timing``: a ``-m`` on the command line replaces
    the ``-m 'not timing'`` of ``addopts``, so the fast tier's ``-m "not slow and ..."``
    (or ``-m slow``) ran the real-time figures that only an idle machine keeps."""
    for item in items:
        for marker, patterns in FILE_MARKERS.items():
            if any(fnmatch(item.path.name, pattern) for pattern in patterns):
                item.add_marker(marker)
    if "timing" in config.getoption("markexpr"):
        return
    timing = [item for item in items if item.get_closest_marker("timing") is not None]
    if timing:
        config.hook.pytest_deselected(items=timing)
        items[:] = [item for item in items if item.get_closest_marker("timing") is None]

#: hole distance along the constrained link for each built-in robot (m)
HOLE_DISTANCE = {"sda10f": 0.08, "ur5_instrument": 0.20}


@pytest.fixture(scope="session", params=sorted(HOLE_DISTANCE))
def robot(request):
    return load_robot(request.param)


@pytest.fixture(scope="session")
def sda10f():
    return load_robot("sda10f")


@pytest.fixture(scope="session")
def ur5_instrument():
    return load_robot("ur5_instrument")


@pytest.fixture(scope="session")
def dual():
    """The two-arm SDA10F (docs/design.md section 11)."""
    return load_robot("sda10f_dual")


@pytest.fixture(scope="session")
def mobile():
    """The two-arm SDA10F on a planar mobile base."""
    return load_robot("sda10f_dual_mobile")


def near_home(robot, rng: np.random.Generator, spread: float = 0.15) -> np.ndarray:
    """A configuration a little away from home (well inside limits, non-singular):
    ``q_home`` moved by a random velocity for 1 s, valid for any joint (a planar base's
    too; for 1-dof joints it is ``q_home + v``)."""
    q = pin.integrate(robot.model, robot.q_home, rng.uniform(-spread, spread, robot.model.nv))
    bounded = np.abs(robot.model.lowerPositionLimit) < 1e10  # not a planar base's
    q[bounded] = np.clip(q[bounded], robot.model.lowerPositionLimit[bounded] + 0.05,
                         robot.model.upperPositionLimit[bounded] - 0.05)
    return q


def kinematics(robot, q: np.ndarray) -> pin.Data:
    """Fresh Pinocchio data with joint Jacobians and frame placements at ``q``."""
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    return data


def ee_jacobian(robot, q: np.ndarray) -> np.ndarray:
    data = kinematics(robot, q)
    return pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame), pin.LOCAL)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> pytest.TestReport:
    """A browser test that fails leaves the page as it was (a screenshot) and its text in
    tests/artifacts, and says so in its report: what a run on a loaded CI machine saw."""
    report = yield
    served = getattr(item, "funcargs", {}).get("web")
    if report.when == "call" and report.failed and served is not None:
        from browser_helpers import record_failed_page

        report.sections.append(("page at the failure", record_failed_page(served, item.name)))
    return report
