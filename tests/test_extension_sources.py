"""The compiled step knows the sources it was built from, and a stale build is not run
(controllers/cjm/extension_sources.py, docs/design.md section 16)."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

from controllers.cjm import _step
from controllers.cjm.controller import CJMController
from controllers.cjm.extension_sources import (SOURCE_DIRECTORY, sources_digest,
                                               stale_extension_reason)
from teleop import load_robot


def digest_written_here(directory: Path) -> str:
    """The digest as the docstring defines it, over the files git lists in _step/."""
    digest = hashlib.sha256()
    for path in sorted(directory.iterdir()):
        if path.name.endswith((".cpp", ".hpp")):
            digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def test_the_built_extension_is_of_the_sources_beside_it():
    assert sources_digest() == digest_written_here(SOURCE_DIRECTORY)
    assert _step.SOURCES_DIGEST == sources_digest()
    assert stale_extension_reason(_step.SOURCES_DIGEST) is None


def test_an_edited_source_makes_the_build_stale(tmp_path: Path):
    copy = tmp_path / "_step"
    shutil.copytree(SOURCE_DIRECTORY, copy, ignore=shutil.ignore_patterns("*.o"))
    assert stale_extension_reason(_step.SOURCES_DIGEST, copy) is None
    step_cpp = copy / "step.cpp"
    step_cpp.write_bytes(step_cpp.read_bytes() + b"\n// an edit after the build\n")
    reason = stale_extension_reason(_step.SOURCES_DIGEST, copy)
    assert reason is not None
    assert "pip install -e ." in reason and sources_digest(copy) in reason
    new_header = copy / "extra.hpp"
    new_header.write_text("#pragma once\n")
    assert sources_digest(copy) == digest_written_here(copy)


def test_no_sources_beside_the_package_means_nothing_to_compare(tmp_path: Path):
    assert stale_extension_reason("0123456789abcdef", tmp_path) is None


def test_a_stale_build_is_refused_by_name_and_auto_runs_the_python_step(monkeypatch):
    import controllers.cjm.controller as controller_module

    monkeypatch.setattr(_step, "SOURCES_DIGEST", "0000000000000000")
    controller_module.compiled_step_problem.cache_clear()
    try:
        robot = load_robot("ur5_instrument")
        with pytest.warns(RuntimeWarning, match="built from other C\\+\\+ sources"):
            auto = CJMController(robot, [], backend="auto")
        assert auto.backend == "python"
        with pytest.raises(ImportError, match="0000000000000000.*rebuild it"):
            CJMController(robot, [], backend="compiled")
    finally:
        monkeypatch.undo()
        controller_module.compiled_step_problem.cache_clear()
    assert CJMController(load_robot("ur5_instrument"), [], backend="auto").backend == "compiled"
