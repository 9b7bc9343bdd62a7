"""Builds the compiled CJM step, ``controllers.cjm._step`` (docs/design.md section 16).

Everything else about the package is in pyproject.toml. The extension needs headers only,
all build requirements: pybind11, Eigen (``cmeel-eigen``), Pinocchio (``libpinocchio``)
and the Boost it uses (``cmeel-boost``). Pinocchio's templates are compiled in; no
Pinocchio library is linked. Baseline x86-64 flags (no ``-march``), so the wheel runs on
any x86-64 machine; no debug information (Pinocchio's templates would make it 100 MB).
"""

from __future__ import annotations

from importlib.metadata import files
from pathlib import Path

from pybind11.setup_helpers import ParallelCompile, Pybind11Extension
from setuptools import setup

SOURCES = sorted(str(path) for path in Path("controllers/cjm/_step").glob("*.cpp"))


def include_dir(wheel: str, header: str) -> str:
    """The include directory holding ``header`` in the installed ``wheel``."""
    for entry in files(wheel) or ():
        if entry.as_posix().endswith(header):
            path = Path(entry.locate())
            return str(path.parents[len(Path(header).parts) - 1])
    raise RuntimeError(f"{header} not found in the {wheel} wheel (a build requirement)")


INCLUDE_DIRS = [include_dir("cmeel-eigen", "Eigen/Core"),
                include_dir("libpinocchio", "pinocchio/multibody.hpp"),
                include_dir("cmeel-boost", "boost/variant.hpp")]
#: what Pinocchio's headers need (its CMake config sets them for its users)
PINOCCHIO_MACROS = [("BOOST_MPL_LIMIT_LIST_SIZE", "30"), ("BOOST_MPL_LIMIT_VECTOR_SIZE", "30"),
                    ("BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", None)]


ParallelCompile("CJM_BUILD_JOBS", default=0).install()

setup(ext_modules=[Pybind11Extension(
    "controllers.cjm._step", SOURCES, include_dirs=INCLUDE_DIRS, cxx_std=17,
    define_macros=PINOCCHIO_MACROS, extra_compile_args=["-g0"],
    depends=[str(p) for p in Path("controllers/cjm/_step").glob("*.hpp")])])
