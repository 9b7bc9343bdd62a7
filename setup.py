"""Builds the compiled CJM step, ``controllers.cjm._step`` (docs/design.md section 16).

Everything else about the package is in pyproject.toml. The extension needs headers only,
all build requirements: pybind11, Eigen (``cmeel-eigen``), Pinocchio (``libpinocchio``)
and the Boost it uses (``cmeel-boost``). Pinocchio's templates are compiled in; no
Pinocchio library is linked. Baseline x86-64 flags (no ``-march``), so the wheel runs on
any x86-64 machine; no debug information (Pinocchio's templates would make it 100 MB).

The extension is built once: each build is kept in ``build/cjm_step/`` under a hash of
what goes into it (the C++ sources and headers, this file, the build requirements'
versions, the compiler and its flags, the Python ABI). A later build with the same hash
(``pip install -e ".[test]"`` after ``pip install -e .``, a reinstall) copies it instead
of compiling for a minute and a half; a clean checkout compiles.

The extension is optional: where it does not compile (no C++ compiler) the install goes
on with one warning line, and ``CJMController(backend="auto")`` runs the Python step.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
import subprocess
import sysconfig
from importlib.metadata import files, version
from pathlib import Path

from pybind11.setup_helpers import ParallelCompile, Pybind11Extension
from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CCompilerError, ExecError, PlatformError


def load_extension_sources():
    """controllers/cjm/extension_sources.py, loaded by path (the package's dependencies
    are not installed yet): the digest of the sources the extension is built from."""
    spec = importlib.util.spec_from_file_location(
        "extension_sources", Path("controllers/cjm/extension_sources.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SOURCES = sorted(str(path) for path in Path("controllers/cjm/_step").glob("*.cpp"))
HEADERS = sorted(str(path) for path in Path("controllers/cjm/_step").glob("*.hpp"))
#: compiled in as ``_step.SOURCES_DIGEST``: an extension of other sources is stale
SOURCES_DIGEST = load_extension_sources().sources_digest(Path("controllers/cjm/_step"))
#: the build requirements the compiled code depends on (pyproject.toml's [build-system])
BUILD_REQUIREMENTS = ("pybind11", "cmeel-eigen", "libpinocchio", "cmeel-boost")
#: where the builds are kept, one file per hash (pip builds in a temporary directory)
BUILD_CACHE = Path(__file__).resolve().parent / "build" / "cjm_step"


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


def compiler_version(command: str) -> str:
    """What ``command --version`` prints (empty when it cannot be run)."""
    try:
        return subprocess.run([command, "--version"], capture_output=True, text=True,
                              timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return ""


class CachedBuildExt(build_ext):
    """``build_ext`` that reuses a kept build of an extension with the same inputs."""

    def build_hash(self, ext: Pybind11Extension) -> str:
        digest = hashlib.sha256()
        for path in map(Path, [*ext.sources, *ext.depends, __file__]):
            digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
        compiler = [*self.compiler.compiler_so, *self.compiler.linker_so]
        for part in [*(f"{name}=={version(name)}" for name in BUILD_REQUIREMENTS),
                     *compiler, compiler_version(self.compiler.compiler_so[0]),
                     *ext.extra_compile_args, *ext.extra_link_args, repr(ext.define_macros),
                     *(f"{name}={os.environ.get(name, '')}" for name in
                       ("CC", "CXX", "CFLAGS", "CXXFLAGS", "CPPFLAGS", "LDFLAGS")),
                     sysconfig.get_config_var("EXT_SUFFIX")]:
            digest.update(part.encode() + b"\0")
        return digest.hexdigest()[:16]

    def build_extension(self, ext: Pybind11Extension) -> None:
        output = Path(self.get_ext_fullpath(ext.name))
        kept = BUILD_CACHE / f"{ext.name.rpartition('.')[2]}-{self.build_hash(ext)}{output.suffix}"
        if kept.is_file():
            print(f"reusing {kept} (same sources, requirements and compiler)")
            output.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(kept, output)
            return
        try:
            super().build_extension(ext)
        except (CCompilerError, ExecError, PlatformError) as error:
            print(f"warning: {ext.name} not built ({error}); the CJM runs its Python step "
                  "(docs/design.md section 16)")
            return
        if self.build_hash(ext) != kept.name.partition("-")[2].partition(".")[0]:
            print("warning: the sources changed during the build; it is not kept")
            return
        try:  # keep this build, alone: the older ones are of other sources
            BUILD_CACHE.mkdir(parents=True, exist_ok=True)
            for old in BUILD_CACHE.glob(f"{kept.name.partition('-')[0]}-*"):
                old.unlink()
            partial = kept.with_name(kept.name + ".partial")
            shutil.copyfile(output, partial)
            partial.replace(kept)
        except OSError as error:
            print(f"warning: the build is not kept for the next one ({error})")


def step_extension() -> Pybind11Extension:
    """The compiled CJM step, ``controllers.cjm._step``."""
    return Pybind11Extension(
        "controllers.cjm._step", SOURCES, include_dirs=INCLUDE_DIRS, cxx_std=17,
        define_macros=[*PINOCCHIO_MACROS, ("CJM_SOURCES_DIGEST", f'"{SOURCES_DIGEST}"')],
        extra_compile_args=["-g0"], depends=HEADERS,
        optional=True)  # setuptools then copies it in place only when it was built


if __name__ == "__main__":
    ParallelCompile("CJM_BUILD_JOBS", default=0).install()
    setup(cmdclass={"build_ext": CachedBuildExt}, ext_modules=[step_extension()])
