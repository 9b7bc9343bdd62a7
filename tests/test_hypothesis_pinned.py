"""The pinned Hypothesis profile draws the same examples whichever project modules are
imported, so a test file run alone meets the examples of the full run (tests/conftest.py,
CONTRIBUTING.md)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: draws 300 floats under the pinned profile, after importing the modules named in argv
DRAWS = """
import importlib, json, sys
sys.path[:0] = [{root!r}, {tests!r}]
import conftest
if sys.argv[1] == "unpatched":
    from hypothesis.internal.conjecture import providers
    providers._get_local_constants = providers.__dict__["_get_local_constants_original"]
for name in sys.argv[2:]:
    importlib.import_module(name)
from hypothesis import given, settings, strategies as st
drawn = []
@settings(max_examples=300)
@given(st.floats(allow_nan=False, allow_infinity=False))
def record(value):
    drawn.append(value)
record()
print(json.dumps([conftest.PROJECT_CONSTANTS_OFF, drawn]))
"""

#: project modules full of float literals (tolerances, options, limits)
MANY_CONSTANTS = ["controllers.cjm.tolerances", "teleop.plants.options", "teleop.limits",
                  "controllers.joint_acceleration", "teleop.loop.supervisor_config"]


def draws(mode: str, modules: list[str]) -> tuple[bool, list[float]]:
    script = DRAWS.format(root=str(ROOT), tests=str(ROOT / "tests"))
    if mode == "unpatched":  # keep the reader the conftest replaces, to restore it
        script = script.replace(
            "import conftest\n",
            "from hypothesis.internal.conjecture import providers\n"
            "providers._get_local_constants_original = providers._get_local_constants\n"
            "import conftest\n", 1)
    env = {**os.environ, "HYPOTHESIS_PROFILE": "pinned", "OPENBLAS_NUM_THREADS": "1"}
    result = subprocess.run([sys.executable, "-c", script, mode, *modules], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=600, check=True)
    patched, drawn = json.loads(result.stdout.strip().splitlines()[-1])
    return patched, drawn


def test_the_examples_do_not_depend_on_the_modules_imported():
    patched, alone = draws("pinned", [])
    assert patched, "this Hypothesis has no local-constants reader to replace: see conftest"
    _, among_modules = draws("pinned", MANY_CONSTANTS)
    assert alone == among_modules


def test_without_the_replacement_the_imported_modules_change_the_examples():
    _, alone = draws("unpatched", [])
    _, among_modules = draws("unpatched", MANY_CONSTANTS)
    assert alone != among_modules
