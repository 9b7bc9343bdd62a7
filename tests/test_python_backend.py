"""A machine without a C++ compiler (docs/design.md section 16): ``pip install`` goes on
when the extension does not compile, and everything runs through the Python step.

``CJM_BACKEND=python`` makes ``backend="auto"`` choose the Python step as if the extension
were not built; the suite's core CJM tests then run in a subprocess with it set, and a
probe (a pytest plugin written here) counts which step every ``auto`` controller built and
how many steps the Python one took."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from constraints import Hole
from controllers import CJMController
from controllers.cjm.compiled import CompiledStep
from controllers.cjm.controller import BACKEND_VARIABLE
from controllers.cjm.python_step import PythonStep

ROOT = Path(__file__).resolve().parent.parent

#: the core tests that build CJM controllers with the default backend: the controllers,
#: the constraints, the dual robots and collision avoidance, the closed loop (every
#: scenario); without the loop's three 10 s runs of every controller held to a micrometre
#: and at the joint limits and the floor (minutes of QP and mink time on a loaded machine)
CORE_TESTS = ("tests/test_controllers.py", "tests/test_constraint_gain.py",
              "tests/test_constraint_placement.py", "tests/test_dual_robots.py",
              "tests/test_collision_cjm.py", "tests/test_loop.py")
CORE_SELECTION = ("not (micrometre or joint_limit_scenario_every_controller"
                  " or barrier_scenario_stops_every_controller)")

PROBE = '''
"""Counts, for the test that runs it, the steps the CJM controllers built and ran."""
import json
import os

from controllers import CJMController
from controllers.cjm.python_step import PythonStep

COUNTS = {"auto_python": 0, "auto_compiled": 0, "python_steps": 0}
_build, _solve = CJMController.__init__, PythonStep.solve


def build(self, *args, **kwargs):
    _build(self, *args, **kwargs)
    if kwargs.get("backend", "auto") == "auto":
        COUNTS["auto_" + self.backend] += 1


def solve(self, q, twist):
    COUNTS["python_steps"] += 1
    return _solve(self, q, twist)


CJMController.__init__, PythonStep.solve = build, solve


def pytest_sessionfinish(session, exitstatus):
    with open(os.environ["CJM_BACKEND_PROBE"], "w", encoding="utf-8") as handle:
        json.dump(COUNTS, handle)
'''


def run_probed(tests: tuple[str, ...], tmp_path: Path, backend: str | None,
               selection: str = "") -> tuple[int, str, dict]:
    """``pytest -k selection tests`` in a subprocess with :data:`PROBE` loaded and
    ``CJM_BACKEND=backend`` (unset for None): its exit code, output and counts."""
    (tmp_path / "cjm_backend_probe.py").write_text(textwrap.dedent(PROBE), encoding="utf-8")
    counts = tmp_path / "counts.json"
    env = {**os.environ, "CJM_BACKEND_PROBE": str(counts), "CI": "true",
           "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT),
                                          os.environ.get("PYTHONPATH", "")])}
    env.pop(BACKEND_VARIABLE, None)
    if backend is not None:
        env[BACKEND_VARIABLE] = backend
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "cjm_backend_probe",
                          "-p", "no:cacheprovider", "-k", selection, *tests], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=3600)
    return run.returncode, run.stdout + run.stderr, json.loads(counts.read_text())


def test_the_core_tests_pass_on_the_python_step(tmp_path):
    code, output, counts = run_probed(CORE_TESTS, tmp_path, "python", CORE_SELECTION)
    assert code == 0, output[-3000:]
    assert counts["auto_compiled"] == 0
    assert counts["auto_python"] >= 50 and counts["python_steps"] >= 10_000, counts


def test_the_probe_sees_the_compiled_step_without_the_variable(tmp_path):
    """The probe can fail: without the variable the same kind of run builds compiled
    steps (this machine has the extension)."""
    code, output, counts = run_probed(("tests/test_constraint_gain.py",), tmp_path, None)
    assert code == 0, output[-3000:]
    assert counts["auto_compiled"] > 0 and counts["auto_python"] == 0


def test_the_variable_chooses_the_step_of_auto_only(sda10f, monkeypatch):
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    monkeypatch.setenv(BACKEND_VARIABLE, "python")
    forced = CJMController(sda10f, [hole])
    assert forced.backend == "python" and type(forced.step) is PythonStep
    assert type(CJMController(sda10f, [hole], backend="compiled").step) is CompiledStep
    monkeypatch.setenv(BACKEND_VARIABLE, "auto")
    chosen = CJMController(sda10f, [hole])
    assert chosen.backend == "compiled" and type(chosen.step) is CompiledStep
    twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])
    q = sda10f.q_home + 1e-3
    np.testing.assert_allclose(forced.solve(q, twist), chosen.solve(q, twist), rtol=0,
                               atol=1e-12)


@pytest.mark.parametrize("value", ["compiled", "pyhton", "0"])
def test_another_value_is_refused_naming_the_variable(sda10f, monkeypatch, value):
    monkeypatch.setenv(BACKEND_VARIABLE, value)
    with pytest.raises(ValueError, match=rf"^CJM_BACKEND must be 'auto' or 'python'.*{value!r}"):
        CJMController(sda10f, [Hole.on_link(sda10f, sda10f.q_home, distance=0.08)])


def test_the_install_goes_on_when_the_extension_does_not_compile(tmp_path):
    """setup.py's build_ext with a compiler that fails: one warning line, no extension,
    no error (``pip install`` goes on); in place, nothing is copied into the source."""
    script = textwrap.dedent(f"""
        import importlib.util, os
        from setuptools import Distribution
        spec = importlib.util.spec_from_file_location("cjm_setup", "setup.py")
        setup = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(setup)
        for inplace in (0, 1):
            dist = Distribution({{"ext_modules": [setup.step_extension()],
                                 "cmdclass": {{"build_ext": setup.CachedBuildExt}},
                                 "packages": ["controllers", "controllers.cjm"]}})
            command = dist.get_command_obj("build_ext")
            command.build_lib = {str(tmp_path / "lib")!r}
            command.build_temp = {str(tmp_path / "temp")!r}
            command.inplace = inplace
            dist.run_command("build_ext")
        """)
    before = sorted(ROOT.glob("controllers/cjm/_step*.so"))
    stamps = [path.stat().st_mtime_ns for path in before]
    failing = str(tmp_path / "no-such-compiler")
    run = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                         text=True, timeout=300, env={**os.environ, "CC": failing, "CXX": failing})
    assert run.returncode == 0, run.stderr
    warnings = [line for line in (run.stdout + run.stderr).splitlines()
                if line.startswith("warning: controllers.cjm._step not built")]
    assert len(warnings) == 2, run.stdout + run.stderr  # one per build
    assert "Python step" in warnings[0]
    assert not list(tmp_path.rglob("_step*.so"))
    assert sorted(ROOT.glob("controllers/cjm/_step*.so")) == before
    assert [path.stat().st_mtime_ns for path in before] == stamps
