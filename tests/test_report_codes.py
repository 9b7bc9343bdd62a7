"""The compiled step's codes from one source (docs/design.md section 16): the statuses,
methods and events of ``_step/report.hpp`` (``CJM_STATUSES``, ``CJM_METHODS``,
``CJM_EVENTS``), bound as dicts and compared with controllers.cjm.report's at import."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from controllers import StepStatus
from controllers.cjm import _step
from controllers.cjm.report import METHODS, NO_METHOD, Event, code_mismatches

ROOT = Path(__file__).resolve().parent.parent
REPORT_HPP = ROOT / "controllers" / "cjm" / "_step" / "report.hpp"


def listed(macro: str) -> list[tuple[str, ...]]:
    """The entries of ``#define macro(X) X(a, ...) X(b, ...)`` in report.hpp, as tuples of
    their arguments (comments dropped)."""
    text = re.sub(r"/\*.*?\*/", "", REPORT_HPP.read_text())
    body = re.search(rf"#define {macro}\((\w+)\)((?:[^\n]*\\\n)*[^\n]*)", text)
    assert body is not None, f"{macro} not in report.hpp"
    name, entries = body.group(1), body.group(2).replace("\\\n", " ")
    return [tuple(part.strip() for part in args.split(","))
            for args in re.findall(rf"\b{name}\(([^)]*)\)", entries)]


def test_the_extension_binds_the_lists_of_report_hpp() -> None:
    """The dicts the extension exports are report.hpp's lists, codes from 0 where none is
    written (so a stale build fails here as at import)."""
    assert _step.STATUSES == {name: code for code, (name,) in enumerate(listed("CJM_STATUSES"))}
    assert _step.METHODS == {name: code for code, (name,) in enumerate(listed("CJM_METHODS"))}
    assert _step.EVENTS == {name: int(code) for name, code in listed("CJM_EVENTS")}
    assert len(_step.EVENTS) == 12 and _step.EVENTS["pair_conflict"] == 14


def test_the_codes_agree_with_python() -> None:
    """Every C++ code is Python's: the events by name, the statuses in StepStatus's order,
    the methods by METHODS' index."""
    assert code_mismatches(_step.EVENTS, _step.STATUSES, _step.METHODS) == []
    for name, code in _step.EVENTS.items():
        assert Event[name.upper()].value == code
    assert [_step.STATUSES[status.value] for status in StepStatus] == [0, 1, 2, 3, 4]
    assert [_step.METHODS[method or NO_METHOD] for method in METHODS] == [0, 1, 2, 3]
    # the two Python-only events use codes C++ leaves free
    assert {Event.PAPER_FORM_UNDEFINED.value,
            Event.LINEAR_ALGEBRA_ERROR.value}.isdisjoint(_step.EVENTS.values())


@pytest.mark.parametrize("events, statuses, methods, words", [
    ({"clipped": 9}, None, None, "event clipped = 9 in C++, CLIPPED = 8 in Python"),
    ({"swept": 15}, None, None, "event swept = 15 in C++, no such event in Python"),
    (None, {"ok": 0, "scaled": 2, "least_squares": 1, "constraint_degraded": 3, "failed": 4},
     None, "status codes"),
    (None, None, {"none": 0, "analytical": 1, "general": 2}, "method codes"),
])
def test_a_mismatch_is_named(events, statuses, methods, words) -> None:
    mismatches = code_mismatches({**_step.EVENTS, **(events or {})},
                                 statuses or _step.STATUSES, methods or _step.METHODS)
    assert len(mismatches) == 1 and words in mismatches[0]


def test_an_extension_with_other_codes_is_an_import_error() -> None:
    """compiled.py refuses an extension whose codes differ, naming the difference."""
    code = ("import controllers.cjm._step as step; step.EVENTS = {**step.EVENTS, 'clipped': 9}; "
            "import controllers.cjm.compiled")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    assert result.returncode == 1
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: controllers.cjm._step's codes are not")
    assert "event clipped = 9 in C++, CLIPPED = 8 in Python" in last and "rebuild" in last
