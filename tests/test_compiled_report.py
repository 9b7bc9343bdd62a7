"""The compiled step's report type ``_step.Report`` (controllers/cjm/_step/report_bindings.hpp,
docs/design.md section 16): a named tuple whose fields read by name are its items, and
whose reads by name CPython specializes as it does ``__slots__`` (compiled.py reads nine
fields a step by name; unspecialized they took 270 ns of the step, issue 37's regression
of the dual robot's and the lock's compiled steps). The interpreter's own record of each
instruction (``dis`` with ``adaptive=True``) says whether a read was specialized: no clock.
"""

from __future__ import annotations

import dis
import os
import sys

import numpy as np
import pytest

from constraints import Hole
from controllers.cjm import CJMController
from controllers.cjm._step import Report
from controllers.cjm.compiled import CompiledStep

#: the fields, in the tuple's order
FIELDS = Report.__match_args__

def cannot_check(reason: str) -> None:
    """Skip on a developer's machine; in CI (``CI`` set) every test runs: fail, naming why."""
    if os.environ.get("CI"):
        pytest.fail(f"CI must run this test: {reason}")
    pytest.skip(reason)


def field_reads(function: object) -> list[dis.Instruction]:
    """The reads of a Report field by name in ``function``, as the interpreter runs them."""
    return [instruction for instruction in dis.get_instructions(function, adaptive=True)
            if instruction.opname.startswith("LOAD_ATTR") and instruction.argval in FIELDS]


def test_each_field_read_by_name_is_its_item():
    values = tuple(float(10 + i) for i in range(len(FIELDS)))
    report = Report(values)
    assert [getattr(report, name) for name in FIELDS] == list(values)
    assert FIELDS[:3] == ("status", "method", "sigma_min")


def test_a_report_keeps_a_field_read_only():
    report = Report(tuple(range(len(FIELDS))))
    with pytest.raises(AttributeError):
        report.status = 3  # type: ignore[misc]


def test_the_compiled_step_reads_its_report_by_name_specialized(sda10f):
    """After a few steps on one hole whose report is read (the fast path: no list, no
    event; a report nobody reads is not built), every read of a field in
    ``CompiledStep.last_report`` is the interpreter's slot read."""
    if sys.version_info < (3, 11):
        cannot_check("CPython specializes attribute reads from 3.11 on")
    if sys.gettrace() is not None:
        cannot_check("a tracer (coverage, a debugger) runs the unspecialized instructions")
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    controller = CJMController(sda10f, [hole], backend="compiled")
    rng = np.random.default_rng(0)
    for _ in range(64):
        controller.solve(sda10f.q_home + rng.uniform(-1e-3, 1e-3, sda10f.model.nq),
                         np.array([0.001, -0.002, 0.0015, 0.005, -0.003, 0.002]))
        assert controller.report.events == ()
    reads = field_reads(CompiledStep.last_report)
    assert reads
    assert {read.opname for read in reads} == {"LOAD_ATTR_SLOT"}
