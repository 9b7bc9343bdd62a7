"""A control period of the MuJoCo plant in one compiled call (docs/design.md section 17.5).

``plant_period.c``, in the library of the ports' walls (:mod:`teleop.plants.compiled_wall`),
does what :meth:`teleop.plants.MujocoPlant.advance` does around ``mj_step`` with the same
arithmetic: each actuator's control from the command, the physics steps with the ports'
walls attached, the torque ratio, the contacts, the velocity that takes the loop's
configuration to the simulated one, ``moved = (qpos - q) / dt`` (``pin.difference`` of
1-dof joints), and the loop's next configuration ``q + moved dt`` (``pin.integrate`` of
them) where the Pinocchio and MuJoCo coordinates are the same (``JointMap.identity``;
elsewhere, a planar base or a continuous joint, Python maps the command in and ``qpos``
out around the call); the buffers it reads and writes are arrays made once, their
addresses given to the C side in one block (:class:`PeriodBlock`). Python calls it through
``period_call.c``, a CPython module compiled as the walls' library is
(:func:`~teleop.plants.cached_build.cached_build`, against Python's and numpy's headers):
one vectorcall copies the command and the configuration in through their buffers, runs the
period without the GIL and returns the two vectors as new arrays (a ctypes call and the
copies around it cost about 0.5 us more).
"""

from __future__ import annotations

import ctypes
import functools
import importlib.machinery
import importlib.util
import sys
import sysconfig
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType

import mujoco
import numpy as np

from constraints import Constraint

from .cached_build import cached_build
from .compiled_wall import PORT_FIELDS, wall_library
from .walls import Wall, wall_of

#: the plant's rows of its ports from the constraints with walls (None: a wall has no
#: compiled form)
PortRows = Callable[[Sequence[tuple[Constraint, Wall]]], np.ndarray | None]

_POINTER = ctypes.c_void_p
#: the call's sources (its module's name is ``cjm_period_call``)
CALL_SOURCES = tuple(Path(__file__).with_name(name)
                     for name in ("period_call.c", "plant_period.h"))
#: the summary's entries (plant_period.c's enum)
RATIO, CONTACTS, PENETRATION = 0, 1, 2


class PeriodBlock(ctypes.Structure):
    """plant_period.h's ``PlantPeriod``: the model, the data, the buffers' addresses, the
    period's function and its sizes."""

    _fields_ = [("model", _POINTER), ("data", _POINTER), ("command", _POINTER), ("q", _POINTER),
                ("actuator_dofs", _POINTER), ("effort_limit", _POINTER), ("ports", _POINTER),
                ("moved", _POINTER), ("reached", _POINTER), ("summary", _POINTER),
                ("run", _POINTER),
                ("dt", ctypes.c_double), ("nstep", ctypes.c_int), ("port_count", ctypes.c_int),
                ("nv", ctypes.c_int), ("nq", ctypes.c_int), ("identity", ctypes.c_int)]


def _address(array: np.ndarray) -> int:
    """The address of ``array``'s first element."""
    return int(array.ctypes.data)


class CompiledPeriod:
    """One plant's period in C: its model and data, the command's buffers, the ports.

    Parameters
    ----------
    library : :func:`~teleop.plants.compiled_wall.wall_library`'s.
    call : :func:`period_call`'s module.
    model, data : the plant's MuJoCo model and data (kept alive here).
    actuator_dofs : (nu,) each actuator's degree of freedom.
    effort_limit : (nv,) each dof's effort limit (``inf``: none).
    dt : the control period (s); ``nstep`` physics steps of it.
    port_rows : the ports' rows (MuJoCo body and site, then the wall's
        ``compiled_parameters``) of the constraints with walls, None when one has no
        compiled form.
    identity : the loop's coordinates are MuJoCo's (:meth:`run`); False: the caller maps
        the command to MuJoCo's dofs and ``qpos`` back (:meth:`run_mapped`).
    """

    def __init__(self, library: ctypes.CDLL, call: ModuleType, model: mujoco.MjModel,
                 data: mujoco.MjData, actuator_dofs: np.ndarray, effort_limit: np.ndarray,
                 dt: float, nstep: int, port_rows: PortRows, identity: bool) -> None:
        self._run, self._run_mapped, self._identical = call.run, call.run_mapped, call.identical
        self._port_rows = port_rows
        #: the constraints with walls, their walls and versions the ports were read from,
        #: and whether every wall there has a compiled form
        self._port_objects: list[object] = []
        self._ports_compiled = True
        self._model, self._data = model, data
        #: the command and the configuration the period starts from, copied in
        self.command, self.q = np.zeros(model.nv), np.zeros(model.nq)
        self._actuator_dofs = np.ascontiguousarray(actuator_dofs, dtype=np.intc)
        self._effort_limit = np.ascontiguousarray(effort_limit, dtype=float)
        #: the velocity ``(qpos - q) / dt`` (rad/s) and the configuration ``q + moved dt``
        #: it takes ``q`` to (``pin.integrate`` of 1-dof joints), written by each period
        self.moved, self.reached = np.zeros(model.nv), np.zeros(model.nq)
        #: the torque ratio, the contact count and the deepest penetration (m)
        self.summary = np.zeros(3)
        #: the ports' blocks (port_wall.c's layout), their results written by the callback
        self.ports = np.zeros((0, PORT_FIELDS))
        self._block = PeriodBlock(model._address, data._address, _address(self.command),
                                  _address(self.q), _address(self._actuator_dofs),
                                  _address(self._effort_limit), _address(self.ports),
                                  _address(self.moved), _address(self.reached),
                                  _address(self.summary),
                                  ctypes.cast(library.cjm_plant_period, _POINTER).value,
                                  float(dt), int(nstep), 0, model.nv, model.nq,
                                  int(identity))
        #: the block's address, as :func:`period_call`'s ``run`` takes it
        self._address = ctypes.addressof(self._block)

    def set_ports(self, ports: np.ndarray) -> None:
        """The ports of the next periods: one row per port, its MuJoCo body and site ids then
        its wall's ``compiled_parameters`` (the results' columns are left to the callback)."""
        if self.ports.shape[0] != ports.shape[0]:
            self.ports = np.zeros((ports.shape[0], PORT_FIELDS))
            self._block.ports = _address(self.ports)
            self._block.port_count = ports.shape[0]
        self.ports[:, :ports.shape[1]] = ports

    def run(self, command: np.ndarray, q: np.ndarray,
            constraints: Sequence[Constraint]) -> tuple[np.ndarray, np.ndarray] | None:
        """One period under ``command`` from ``q`` with the walls of ``constraints``; the
        velocity moved and the configuration it takes ``q`` to over the period (new
        arrays), or None (nothing run) when a wall has no compiled form (:meth:`ports_ready`).
        Only with ``identity``."""
        if not self.ports_ready(constraints):
            return None
        try:  # copied through their buffers (float64 vectors of the right size: the loop's)
            ran: tuple[np.ndarray, np.ndarray] = self._run(self._address, command, q)
        except TypeError:  # another type, layout or shape: numpy's copy and checks
            np.copyto(self.command, command)
            np.copyto(self.q, q)
            ran = self._run(self._address, self.command, self.q)
        return ran

    def run_mapped(self, command: np.ndarray, constraints: Sequence[Constraint]) -> bool:
        """One period under ``command`` (MuJoCo's dofs, float64) with the walls of
        ``constraints``, the caller reading ``qpos``; False (nothing run) when a wall has no
        compiled form."""
        if not self.ports_ready(constraints):
            return False
        self._run_mapped(self._address, command)
        return True

    def ports_ready(self, constraints: Sequence[Constraint]) -> bool:
        """The ports of ``constraints``' walls in the block, False when a wall has no
        compiled form. They are read again when a constraint, its wall or an object of the
        wall's :meth:`~teleop.plants.walls.Wall.compiled_version` is not the last period's
        (``is``: a replaced object is read again even when it holds the same numbers)."""
        objects: list[object] = []
        for constraint in constraints:
            wall = wall_of(constraint)
            if wall is not None:
                objects += (constraint, wall, *wall.compiled_version(constraint))
        if not self._identical(objects, self._port_objects):
            rows = self._port_rows([(constraint, wall) for constraint in constraints
                                    if (wall := wall_of(constraint)) is not None])
            self._ports_compiled = rows is not None
            if rows is not None:
                self.set_ports(rows)
            self._port_objects = objects
        return self._ports_compiled


def compiled_period(model: mujoco.MjModel, data: mujoco.MjData, actuator_dofs: np.ndarray,
                    effort_limit: np.ndarray, dt: float, nstep: int,
                    port_rows: PortRows, identity: bool) -> CompiledPeriod | None:
    """The compiled period of a plant, or None where the library or the call is not
    available."""
    library, call = wall_library(), period_call()
    return (None if library is None or call is None else
            CompiledPeriod(library, call, model, data, actuator_dofs, effort_limit, dt, nstep,
                           port_rows, identity))


@functools.cache
def period_call() -> ModuleType | None:
    """``period_call.c`` built (once, kept in the cache) against this Python's and numpy's
    headers and imported; None where that is not possible."""
    target = cached_build("period_call", CALL_SOURCES,
                          [f"-I{sysconfig.get_path('include')}", f"-I{np.get_include()}"],
                          f"{sys.version} {np.__version__}")
    if target is None:
        return None
    loader = importlib.machinery.ExtensionFileLoader("cjm_period_call", str(target))
    spec = importlib.util.spec_from_loader("cjm_period_call", loader)
    if spec is None:
        return None
    try:
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
    except (ImportError, OSError):
        return None
    return module
