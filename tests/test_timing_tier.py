"""The ``timing`` tests run only when asked for by name (CONTRIBUTING.md, tests/conftest.py):
a ``-m`` on the command line replaces the ``-m 'not timing'`` of ``addopts``, so without
the conftest's rule the fast tier's ``-m "not slow and ..."`` and ``-m slow`` ran real-time
figures that a loaded machine cannot keep. Collected by pytest in a process of its own."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: a file of one test, marked ``timing``
TIMING_FILE = "tests/test_floods_timing.py"
TIMING_TEST = f"{TIMING_FILE}::test_the_loop_keeps_nine_tenths_of_its_rate_under_both_floods"


def collected(*options: str) -> list[str]:
    """The test ids pytest collects from ``TIMING_FILE`` with these options."""
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
         *options, TIMING_FILE], capture_output=True, text=True, cwd=ROOT, timeout=300,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    assert result.returncode in (0, 5), result.stdout[-2000:] + result.stderr[-2000:]  # 5: none
    return [line for line in result.stdout.splitlines() if "::" in line]


@pytest.mark.parametrize("options", [
    (), ("-m", "not slow and not browser and not physics and not fuzz")],
    ids=["default", "fast tier"])
def test_a_run_that_does_not_name_timing_leaves_the_timing_tests_out(options):
    assert collected(*options) == []


def test_a_run_that_names_timing_collects_them():
    assert collected("-m", "timing and not browser") == [TIMING_TEST]
