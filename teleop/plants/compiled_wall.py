"""The ports' walls applied by compiled code inside ``mj_step`` (docs/design.md section 17.5).

``port_wall.c`` is MuJoCo's passive-force callback (``mjcb_passive``) with the math of
:class:`teleop.plants.walls.PortWall`. It is compiled once with the machine's C compiler
against the ``mujoco`` wheel's headers and library, kept under the user's cache directory
by a hash of its sources, the compiler and MuJoCo's version
(:func:`~teleop.plants.cached_build.cached_build`), loaded by ctypes and installed
as the process's callback (a C function pointer: MuJoCo calls it without the GIL). A
plant attaches its MjData and its ports' parameters for one ``mj_step(m, d, nstep)`` call
(:meth:`CompiledPorts.step`), so a period with holes is one call, as one without. The
attachment is the stepping thread's own (MuJoCo calls the callback in the thread that
called ``mj_step``): plants in several threads each step with their own ports. The same
library holds the plant's whole period (``plant_period.c``, :mod:`.compiled_period`).

Where it cannot be built or loaded (no compiler, not Linux, another callback already
installed) :func:`compiled_ports` is None and the plant applies the walls from Python,
splitting each physics step (``mj_step1``, the forces, ``mj_step2``): the same forces.
"""

from __future__ import annotations

import ctypes
import functools
import sys
from pathlib import Path

import mujoco
import numpy as np

from .cached_build import cached_build

#: the library's sources: the walls' callback, and the plant's period around ``mj_step``
#: (``plant_period.c``, :mod:`teleop.plants.compiled_period`)
SOURCES = tuple(Path(__file__).with_name(name)
                for name in ("port_wall.c", "plant_period.c", "plant_period.h"))
#: one port's block of doubles (port_wall.c's enum): body and site ids, then
#: PortWall.compiled_parameters (link axis, centre, centre velocity, stiffness, damping),
#: then what the callback writes (force, spring part, displacement)
PORT_FIELDS = 2 + 11 + 7
FORCE, SPRING, DISPLACEMENT = 13, 16, 19


class CompiledPorts:
    """The compiled walls of one plant's MjData (the ports' parameters given every period)."""

    def __init__(self, library: ctypes.CDLL, data: mujoco.MjData) -> None:
        self._library = library
        self._data = data
        self._address = ctypes.c_void_p(data._address)
        self.ports = np.zeros((0, PORT_FIELDS))
        #: :attr:`ports`' buffer as the C callback reads it (made again when it is reallocated)
        self._pointer = self.ports.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def step(self, model: mujoco.MjModel, ports: np.ndarray, nstep: int) -> None:
        """``nstep`` physics steps with the walls of ``ports``: one row per port, its
        MuJoCo body and site ids then its wall's ``compiled_parameters``."""
        if self.ports.shape[0] != ports.shape[0]:
            self.ports = np.zeros((ports.shape[0], PORT_FIELDS))
            self._pointer = self.ports.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        self.ports[:, :FORCE] = ports
        self._library.cjm_wall_attach(self._address, self._pointer, len(self.ports))
        try:
            mujoco.mj_step(model, self._data, nstep)
        finally:
            self._library.cjm_wall_detach(self._address)

    def results(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:attr:`forces`, :attr:`springs` and :attr:`displacements` from one copy of the
        ports' results (views of it)."""
        written = self.ports[:, FORCE:].copy()
        return (written[:, :SPRING - FORCE], written[:, SPRING - FORCE:DISPLACEMENT - FORCE],
                written[:, DISPLACEMENT - FORCE])

    @property
    def forces(self) -> np.ndarray:
        """Each port's force at the last physics step (N, world)."""
        return self.ports[:, FORCE:FORCE + 3].copy()

    @property
    def springs(self) -> np.ndarray:
        """Each force's spring part ``-k (P - c)`` (N)."""
        return self.ports[:, SPRING:SPRING + 3].copy()

    @property
    def displacements(self) -> np.ndarray:
        """Each port's ``|P - c|`` (m)."""
        return self.ports[:, DISPLACEMENT].copy()


@functools.cache
def wall_library() -> ctypes.CDLL | None:
    """``port_wall.c`` built (once, kept in the cache), loaded and installed as MuJoCo's
    passive callback; None where that is not possible."""
    if not sys.platform.startswith("linux") or mujoco.get_mjcb_passive() is not None:
        return None
    package = Path(mujoco.__file__).resolve().parent
    libraries = sorted(package.glob("libmujoco.so*"))
    if not libraries or not (package / "include" / "mujoco" / "mujoco.h").is_file():
        return None
    target = cached_build("port_wall", SOURCES,
                          [f"-I{package / 'include'}", str(libraries[0]),
                           f"-Wl,-rpath,{package}", "-lm", "-ffp-contract=off"],
                          mujoco.__version__)
    if target is None:
        return None
    try:
        library = ctypes.CDLL(str(target))
    except OSError:
        return None
    library.cjm_wall_attach.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.c_int]
    library.cjm_wall_attach.restype = None
    library.cjm_wall_detach.argtypes = [ctypes.c_void_p]
    library.cjm_wall_detach.restype = None
    mujoco.set_mjcb_passive(library.cjm_wall_passive)
    return library


def compiled_ports(data: mujoco.MjData) -> CompiledPorts | None:
    """The compiled walls for ``data``'s ports, or None where the library is not
    available."""
    library = wall_library()
    return None if library is None else CompiledPorts(library, data)
