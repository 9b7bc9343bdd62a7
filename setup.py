"""Builds the compiled CJM step, ``controllers.cjm._step`` (docs/design.md section 16).

Everything else about the package is in pyproject.toml. The extension needs only Eigen's
headers (the ``cmeel-eigen`` wheel) and pybind11, both build requirements; it is built
with baseline x86-64 flags (no ``-march``), so the wheel runs on any x86-64 machine.
"""

from __future__ import annotations

from importlib.metadata import files
from pathlib import Path

from pybind11.setup_helpers import ParallelCompile, Pybind11Extension
from setuptools import setup

SOURCES = sorted(str(path) for path in Path("controllers/cjm/_step").glob("*.cpp"))


def eigen_include() -> str:
    """The directory holding ``Eigen/Core`` in the ``cmeel-eigen`` wheel."""
    for entry in files("cmeel-eigen") or ():
        if entry.as_posix().endswith("eigen3/Eigen/Core"):
            return str(Path(entry.locate()).parent.parent)
    raise RuntimeError("Eigen's headers not found in the cmeel-eigen wheel")


ParallelCompile("CJM_BUILD_JOBS", default=0).install()

setup(ext_modules=[Pybind11Extension(
    "controllers.cjm._step", SOURCES, include_dirs=[eigen_include()], cxx_std=17,
    depends=[str(p) for p in Path("controllers/cjm/_step").glob("*.hpp")])])
