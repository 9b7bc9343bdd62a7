"""Robot models: a Pinocchio model plus what the teleoperation controllers need.

Four robots ship with the package (primitive geometry, nothing downloaded, see docs/design.md
sections 6 and 11): ``"sda10f"`` (torso + 7-axis arm, the paper's experiment),
``"ur5_instrument"`` (UR5-like arm holding a surgical instrument with a 2-DoF wrist),
``"sda10f_dual"`` (torso + both arms, an EE and a trocar link per arm) and
``"sda10f_dual_mobile"`` (the same on a planar mobile base). Any other URDF loads from its
path.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import types
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from constraints.validation import as_vector

from .home import check_home, default_home, joint_box, sampling_bounds

__all__ = ["Robot", "load_robot", "BUILTIN_ROBOTS"]

ROBOTS_DIR = pathlib.Path(__file__).resolve().parent

#: Defaults of the shipped robots: urdf file (in ``teleop/robots``), EE frame(s), constrained
#: link(s) with the link axis (in constrained-link coordinates), root joint, home configuration.
BUILTIN_ROBOTS: Mapping[str, Mapping[str, Any]] = types.MappingProxyType({
    "sda10f": types.MappingProxyType({
        "urdf": "sda10f.urdf",
        "ee_frame": "tool0",
        "constrained_link": "arm_link_5_r",
        "link_axis": (0.0, 0.0, -1.0),
        # arm reaching forward in front of the torso, elbow out, wrist bent (joint B at
        # -1.2 rad keeps joint T away from the link axis: B = 0 makes the CJM singular)
        "q_home": (0.0, 0.0, 1.3, 0.8, -1.1, 0.5, -1.2, 0.6),
    }),
    "ur5_instrument": types.MappingProxyType({
        "urdf": "ur5_instrument.urdf",
        "ee_frame": "tool_tip",
        "constrained_link": "instrument_shaft",
        "link_axis": (0.0, 0.0, 1.0),
        # elbow up, shaft pointing straight down (world -z), tip at about (0.53, 0.11, -0.16)
        "q_home": (np.pi, -1.4, 1.8, -0.4 - np.pi / 2, -np.pi / 2, 0.0, 0.0, 0.0),
    }),
    # the torso and both arms (left: the sda10f's), a trocar on each arm's link 6; joint L
    # at 0.9 (not 1.3): at 1.3 the left tool crosses the mid-plane and the mirrored arms collide
    "sda10f_dual": types.MappingProxyType({
        "urdf": "sda10f_dual.urdf",
        "ee_frames": ("arm_left_link_tool0", "arm_right_link_tool0"),
        "constrained_links": (("arm_left_link_5_r", (0.0, 0.0, -1.0)),
                              ("arm_right_link_5_r", (0.0, 0.0, -1.0))),
        "q_home": (0.0, 0.0, 0.9, 0.8, -1.1, 0.5, -1.2, 0.6,
                   0.0, 0.9, 0.8, -1.1, 0.5, -1.2, 0.6),
    }),
    # the same on a mobile base (planar root joint: x, y, cos, sin of the heading)
    "sda10f_dual_mobile": types.MappingProxyType({
        "urdf": "sda10f_dual_mobile.urdf",
        "root_joint": "planar",
        "root_velocity_limit": (0.5, 0.5, 1.0),
        "ee_frames": ("arm_left_link_tool0", "arm_right_link_tool0"),
        "constrained_links": (("arm_left_link_5_r", (0.0, 0.0, -1.0)),
                              ("arm_right_link_5_r", (0.0, 0.0, -1.0))),
        "q_home": (0.0, 0.0, 1.0, 0.0,
                   0.0, 0.0, 0.9, 0.8, -1.1, 0.5, -1.2, 0.6,
                   0.0, 0.9, 0.8, -1.1, 0.5, -1.2, 0.6),
    }),
})


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Robot:
    """A kinematic model with its geometry, end-effector frame and constrained link.

    Attributes
    ----------
    name : robot name (built-in name or the URDF's robot name).
    model : Pinocchio kinematic model (fixed base, or on a planar root joint: then
        ``nq != nv``).
    visual_model, collision_model : geometry (empty if the meshes could not be found).
    urdf_path : the URDF file the model was built from.
    ee_frame : name of the (first) end-effector frame.
    q_home : (nq,) read-only home configuration; use ``robot.q_home.copy()``.
    constrained_link : name of the (first) link carrying a constraint point, or None.
    link_axis : (3,) read-only unit vector, the long direction of ``constrained_link`` in
        its own coordinates.
    ee_frames : every end-effector frame, ``ee_frame`` first. Controllers take a twist of
        6 entries per frame, in this order (docs/design.md section 11).
    constrained_links : every link that carries an instrument through a constraint (one
        per arm), ``constrained_link`` first; empty when there is none.
    link_axes : the long axis of each of ``constrained_links``, read-only.
    root_joint : ``"fixed"``, or ``"planar"`` for a mobile base (x, y, heading).
    acceleration_limit : (nv,) read-only per-joint acceleration limits (rad/s^2, m/s^2 for
        prismatic joints and a base's translations; ``inf`` for none), or None when the
        robot has none (:func:`acceleration_limits`, docs/design.md section 8.4).
    package_dirs : directories searched for ``package://`` meshes.
    locked_joints : the URDF joints frozen out of ``model`` by ``load_robot(...,
        locked_joints=...)``, each with the configuration coordinates it is held at
        (``model`` has none of them; the URDF at ``urdf_path`` still does). Read-only.
    """

    name: str
    model: pin.Model = field(repr=False)
    visual_model: pin.GeometryModel = field(repr=False)
    collision_model: pin.GeometryModel = field(repr=False)
    urdf_path: pathlib.Path
    ee_frame: str
    q_home: np.ndarray
    constrained_link: str | None
    link_axis: np.ndarray
    package_dirs: tuple[str, ...]
    locked_joints: Mapping[str, tuple[float, ...]] = field(
        default_factory=lambda: types.MappingProxyType({}))
    ee_frames: tuple[str, ...] = ()
    constrained_links: tuple[str, ...] = ()
    link_axes: Mapping[str, np.ndarray] = field(
        default_factory=lambda: types.MappingProxyType({}))
    root_joint: str = "fixed"
    acceleration_limit: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        # a Robot built field by field (single EE) gets the tuples from the single names
        if not self.ee_frames:
            object.__setattr__(self, "ee_frames", (self.ee_frame,))
        if not self.constrained_links and self.constrained_link is not None:
            object.__setattr__(self, "constrained_links", (self.constrained_link,))
        if not self.link_axes and self.constrained_link is not None:
            object.__setattr__(self, "link_axes", types.MappingProxyType(
                {self.constrained_link: self.link_axis}))

    @property
    def ee_frame_id(self) -> int:
        """Frame id of the end effector."""
        return self.model.getFrameId(self.ee_frame)

    @property
    def ee_frame_ids(self) -> tuple[int, ...]:
        """Frame ids of every end effector, in ``ee_frames`` order."""
        return tuple(self.model.getFrameId(name) for name in self.ee_frames)

    @property
    def task_size(self) -> int:
        """Entries of the stacked EE twist a controller takes: 6 per end effector."""
        return 6 * len(self.ee_frames)

    @property
    def constrained_frame_id(self) -> int | None:
        """Frame id of the constrained link (None when there is none)."""
        if self.constrained_link is None:
            return None
        return self.model.getFrameId(self.constrained_link)

    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def nv(self) -> int:
        return self.model.nv

    def random_configuration(self, rng: np.random.Generator, margin: float = 0.1) -> np.ndarray:
        """Uniform configuration inside ``[lower + margin*range, upper - margin*range]``.

        Unbounded coordinates are drawn in ``[-pi, pi]`` (same margin); the result is
        normalised (``pin.normalize``) so quaternion / unit-complex joints stay valid.
        """
        if not 0.0 <= margin < 0.5:
            raise ValueError(f"margin must be in [0, 0.5), got {margin}")
        lo, hi = sampling_bounds(self.model)
        span = hi - lo
        q = rng.uniform(lo + margin * span, hi - margin * span)
        return pin.normalize(self.model, q)


def _frame_names(model: pin.Model) -> list[str]:
    return [f.name for f in model.frames if f.type == pin.FrameType.BODY]


def _check_frame(model: pin.Model, name: str, what: str) -> str:
    if not isinstance(name, str) or not model.existFrame(name):
        raise ValueError(f"unknown {what} {name!r}; link (body) frames of this model: {_frame_names(model)}")
    return name


def _check_axis(link_axis: Any) -> np.ndarray:
    """A link axis of any non-zero length, normalised (a direction, not a unit vector)."""
    axis = as_vector(link_axis, 3, "link_axis")
    scale = float(np.max(np.abs(axis)))  # the norm of axis / scale cannot overflow
    if scale < 1e-12:
        raise ValueError(f"link_axis must be non-zero, got {link_axis!r}")
    axis = axis / scale
    return axis / float(np.linalg.norm(axis))


def _check_q_home(model: pin.Model, q_home: Any, what: str = "q_home",
                  checked: np.ndarray | None = None) -> np.ndarray:
    """``q_home`` as a finite (nq,) array inside the position limits at the indices
    ``checked`` (default: all), else ``ValueError`` naming ``what``."""
    try:
        q = np.asarray(q_home, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a vector of {model.nq} numbers, got {q_home!r}") from None
    if q.shape != (model.nq,):
        raise ValueError(f"{what} must have size nq = {model.nq}, got shape {q.shape}")
    if not np.all(np.isfinite(q)):  # which joints, not only that (as_vector would say less)
        raise ValueError(f"{what} has non-finite entries at indices "
                         f"{np.flatnonzero(~np.isfinite(q)).tolist()}")
    outside = (q < model.lowerPositionLimit) | (q > model.upperPositionLimit)
    if checked is not None:
        outside &= np.isin(np.arange(model.nq), checked)
    bad = np.flatnonzero(outside)
    if bad.size:
        raise ValueError(
            f"{what} is outside the position limits at indices {bad.tolist()}: "
            f"q = {q[bad].tolist()}, lower = {model.lowerPositionLimit[bad].tolist()}, "
            f"upper = {model.upperPositionLimit[bad].tolist()}"
        )
    return q


def _joint_ids_to_lock(model: pin.Model, locked_joints: Any) -> list[int]:
    """Pinocchio joint ids of the joint names in ``locked_joints`` (``ValueError`` otherwise)."""
    if isinstance(locked_joints, (str, bytes)) or not isinstance(locked_joints, Iterable):
        raise ValueError(f"locked_joints must be a list of joint names, got {locked_joints!r}")
    names = list(locked_joints)
    movable = [model.names[j] for j in range(1, model.njoints)]
    for name in names:
        if not isinstance(name, str) or name not in movable:
            raise ValueError(f"locked_joints: unknown joint {name!r}; the movable joints of this "
                             f"model are {movable}")
    if len(set(names)) != len(names):
        raise ValueError(f"locked_joints names a joint twice: {names}")
    if len(names) == len(movable):
        raise ValueError(f"locked_joints would lock every joint {movable}: nothing left to control")
    return sorted(model.getJointId(name) for name in names)


def _lock_joints(model: pin.Model, geometry: tuple[pin.GeometryModel, pin.GeometryModel],
                 joint_ids: list[int], configuration: np.ndarray
                 ) -> tuple[pin.Model, pin.GeometryModel, pin.GeometryModel, np.ndarray,
                            dict[str, tuple[float, ...]]]:
    """``model`` with the joints ``joint_ids`` frozen at ``configuration`` (Pinocchio's
    ``buildReducedModel``), its two geometry models, the configuration indices of the
    kept coordinates, and each locked joint's name with the coordinates it is held at.

    Every frame keeps its name; its placement at a configuration of the reduced model is
    the full model's at the same kept coordinates, the locked ones from ``configuration``.
    """
    reduced, (visual, collision) = pin.buildReducedModel(model, list(geometry), joint_ids,
                                                         configuration)
    kept = np.setdiff1d(np.arange(model.nq), _coordinates(model, joint_ids))
    locked = {model.names[j]: tuple(float(x) for x in configuration[_coordinates(model, [j])])
              for j in joint_ids}
    return reduced, visual, collision, kept, locked


def _coordinates(model: pin.Model, joint_ids: list[int]) -> np.ndarray:
    """Configuration indices of the joints ``joint_ids``, in order."""
    return np.array([i for j in joint_ids
                     for i in range(model.idx_qs[j], model.idx_qs[j] + model.nqs[j])], dtype=int)


#: Root joints a robot may stand on: a fixed base, or a mobile base moving in the plane.
ROOT_JOINTS = ("fixed", "planar")


def _build_model(urdf: pathlib.Path, root_joint: str = "fixed") -> pin.Model:
    try:
        if root_joint == "planar":
            return pin.buildModelFromUrdf(str(urdf), pin.JointModelPlanar())
        return pin.buildModelFromUrdf(str(urdf))
    except (ValueError, RuntimeError) as exc:
        detail = str(exc)
        try:  # the XML parser says where the file is broken; Pinocchio only that it is
            ET.parse(urdf)
        except ET.ParseError as xml_exc:
            detail += f" (XML error: {xml_exc})"
        raise ValueError(f"cannot parse URDF {urdf}: {detail}") from exc


def _build_geometry(model: pin.Model, urdf: pathlib.Path, package_dirs: tuple[str, ...]
                    ) -> tuple[pin.GeometryModel, pin.GeometryModel]:
    models = []
    for kind in (pin.GeometryType.VISUAL, pin.GeometryType.COLLISION):
        try:
            models.append(pin.buildGeomFromUrdf(model, str(urdf), kind, package_dirs=list(package_dirs)))
        except (ValueError, RuntimeError) as exc:
            warnings.warn(
                f"{urdf}: could not load the {kind.name.lower()} geometry ({exc}); using an empty "
                f"geometry model (kinematics unaffected). Searched package_dirs: {list(package_dirs)}",
                stacklevel=3,
            )
            models.append(pin.GeometryModel())
    return models[0], models[1]


class RobotNotFound(FileNotFoundError, ValueError):
    """Neither a built-in robot's name nor the path of a URDF file."""


def load_robot(
    name_or_urdf_path: str | os.PathLike,
    ee_frame: str | None = None,
    constrained_link: str | None = None,
    link_axis: Any = None,
    package_dirs: Any = None,
    q_home: Any = None,
    locked_joints: Iterable[str] | None = None,
    locked_configuration: Any = None,
    ee_frames: Iterable[str] | None = None,
    root_joint: str | None = None,
    root_velocity_limit: Any = None,
    acceleration_limit: Any = None,
) -> Robot:
    """Load a built-in robot by name, or any URDF by path.

    Parameters
    ----------
    name_or_urdf_path : a key of ``BUILTIN_ROBOTS`` or the path of a URDF file.
    ee_frame : end-effector frame. Default: the built-in's, else the LAST body (link) frame
        in ``model.frames``.
    constrained_link : link carrying the constraint point. Default: the built-in's, else None.
    link_axis : (3,) long direction of the constrained link in its own coordinates,
        normalised. Default: the built-in's, else (0, 0, 1).
    package_dirs : directories where ``package://`` meshes are looked up. Default: the
        directories containing the URDF (its folder and all its ancestors).
    q_home : (nq,) home configuration inside the limits, of the URDF's joints (the
        locked ones included). Default: the built-in's, else one inside the limits by a
        margin and away from singularities (``teleop.robots.home.default_home``,
        docs/design.md section 6.1). A given one near a bound or singular is taken with
        a ``HomeWarning``.
    locked_joints : names of URDF joints to freeze (grippers, fingers): the robot's model
        is Pinocchio's ``buildReducedModel`` of the URDF's without them, so no controller
        sees or moves them. The frames they carry stay, rigidly attached to the parent.
    locked_configuration : (nq,) configuration of the URDF's joints the locked joints
        are held at (only their entries are read). Default: ``q_home``.
    ee_frames : several end-effector frames (one per arm), instead of ``ee_frame``.
    root_joint : ``"fixed"`` (default) or ``"planar"``: the URDF's root link on a mobile
        base moving in the plane (x, y, heading: 4 configuration, 3 velocity coordinates).
    root_velocity_limit : (3,) velocity limits of a planar root joint (m/s, m/s, rad/s).
        Default: the built-in's, else (0.5, 0.5, 1.0).

    Raises
    ------
    RobotNotFound : the path does not exist (and is not a built-in name); both a
        ``FileNotFoundError`` and a ``ValueError``.
    ValueError : unparsable URDF, unknown frame, bad ``link_axis``, ``q_home``,
        ``locked_joints`` or ``locked_configuration``.

    If the geometry cannot be loaded (e.g. missing meshes) a warning is emitted and the
    robot gets empty geometry models: the kinematics are all the controllers need.
    """
    if not isinstance(name_or_urdf_path, (str, os.PathLike)) or not os.fspath(name_or_urdf_path):
        raise ValueError(f"robot must be a built-in robot name or a URDF path, got "
                         f"{name_or_urdf_path!r} (built-in robots: {sorted(BUILTIN_ROBOTS)})")
    for option, value in (("ee_frame", ee_frame), ("constrained_link", constrained_link),
                          ("root_joint", root_joint)):
        if value is not None and not isinstance(value, str):
            raise ValueError(f"{option} must be a name, got {value!r}")
    lists: tuple[tuple[str, Any, type | tuple[type, ...]], ...] = (
        ("ee_frames", ee_frames, str), ("package_dirs", package_dirs, (str, os.PathLike)))
    for option, given, kinds in lists:
        listed = given if isinstance(given, (list, tuple)) else ()
        if not isinstance(given, (type(None), str, os.PathLike, Iterable)) or not all(
                isinstance(item, kinds) for item in listed):
            raise ValueError(f"{option} must be a list of names, got {given!r}")
    key = os.fspath(name_or_urdf_path)
    builtin = isinstance(key, str) and key in BUILTIN_ROBOTS
    if builtin:
        defaults = BUILTIN_ROBOTS[key]
        urdf = ROBOTS_DIR / defaults["urdf"]
    else:
        urdf = pathlib.Path(key).expanduser()
        if not urdf.is_file():
            raise RobotNotFound(
                f"no URDF file at {str(urdf)!r} and not a built-in robot name "
                f"(built-in robots: {sorted(BUILTIN_ROBOTS)})"
            )
        defaults = {"ee_frame": None, "constrained_link": None, "link_axis": (0.0, 0.0, 1.0), "q_home": None}
    urdf = urdf.resolve()

    root_joint = root_joint if root_joint is not None else defaults.get("root_joint", "fixed")
    if root_joint not in ROOT_JOINTS:
        raise ValueError(f"unknown root_joint {root_joint!r}: one of {list(ROOT_JOINTS)}")
    model = _build_model(urdf, root_joint)
    if root_joint == "planar":
        _limit_root_velocity(model, root_velocity_limit if root_velocity_limit is not None
                             else defaults.get("root_velocity_limit", DEFAULT_ROOT_VELOCITY_LIMIT))
    elif root_velocity_limit is not None:
        raise ValueError("root_velocity_limit is given but the robot has no planar root joint")
    joint_ids_to_lock = [] if locked_joints is None else _joint_ids_to_lock(model, locked_joints)
    if locked_configuration is not None and not joint_ids_to_lock:
        raise ValueError("locked_configuration is given but locked_joints names no joint")
    if package_dirs is None:
        package_dirs = [urdf.parent, *urdf.parent.parents]
    elif isinstance(package_dirs, (str, os.PathLike)):
        package_dirs = [package_dirs]
    package_dirs = tuple(os.fspath(p) for p in package_dirs)
    visual_model, collision_model = _build_geometry(model, urdf, package_dirs)

    given = q_home is not None
    if q_home is None:
        q_home = defaults["q_home"]
    if q_home is None:  # a start for default_home, below; the locked joints stay there
        box = joint_box(model)
        q = pin.neutral(model)
        q[box.q_index] = np.clip(q[box.q_index], *box.inner())
    else:
        q = _check_q_home(model, q_home)
    locked: dict[str, tuple[float, ...]] = {}
    if joint_ids_to_lock:
        held = q if locked_configuration is None else _check_q_home(
            model, locked_configuration, "locked_configuration",
            checked=_coordinates(model, joint_ids_to_lock))
        model, visual_model, collision_model, kept, locked = _lock_joints(
            model, (visual_model, collision_model), joint_ids_to_lock, held)
        q = q[kept]

    frames = _ee_frames(model, ee_frame, ee_frames, defaults)
    links = _constrained_links(model, constrained_link, link_axis, defaults)
    # the first link's axis; a robot without one keeps the axis for links named later
    axis = next(iter(links.values()), None)
    if axis is None:
        axis = _readonly(_check_axis(link_axis if link_axis is not None
                                     else defaults.get("link_axis", (0.0, 0.0, 1.0))))

    robot = Robot(
        name=key if builtin else model.name,
        model=model,
        visual_model=visual_model,
        collision_model=collision_model,
        urdf_path=urdf,
        ee_frame=frames[0],
        q_home=_readonly(q),
        constrained_link=next(iter(links), None),
        link_axis=axis,
        package_dirs=package_dirs,
        locked_joints=types.MappingProxyType(locked),
        ee_frames=frames,
        constrained_links=tuple(links),
        link_axes=types.MappingProxyType(links),
        root_joint=root_joint,
        acceleration_limit=acceleration_limits(model, urdf, acceleration_limit,
                                               root_joint == "planar"),
    )
    if given:
        check_home(robot, robot.q_home)
    elif q_home is None:
        robot = dataclasses.replace(robot, q_home=_readonly(default_home(robot, robot.q_home)))
    return robot


#: Seconds a joint takes from rest to its velocity limit at its default acceleration limit
#: (every robot whose URDF gives no ``<limit acceleration>``). The makers publish joint
#: speeds (Yaskawa's SDA10F datasheet: 130-400 deg/s, the URDFs' velocity limits) but no
#: joint accelerations; 0.2 s to full speed is an engineering choice typical of arms of
#: this class (docs/design.md section 8.4).
ACCELERATION_RAMP_TIME = 0.2

#: Default acceleration limits of a built-in planar base (m/s^2, m/s^2, rad/s^2): 0.5 s to
#: its default speed (0.5 m/s, 1 rad/s), about 0.1 g, an engineering choice for a wheeled
#: base carrying a dual-arm torso.
ROOT_ACCELERATION_LIMIT = (1.0, 1.0, 2.0)


def urdf_acceleration_limits(urdf: pathlib.Path) -> dict[str, float]:
    """``{joint name: limit}`` of the URDF's joints whose ``<limit>`` carries an
    ``acceleration`` attribute (rad/s^2 or m/s^2; not part of the URDF standard, read when
    present). A value that is not a positive number raises ``ValueError`` (file:joint)."""
    limits = {}
    for joint in ET.parse(urdf).getroot().iter("joint"):
        limit = joint.find("limit")
        text = None if limit is None else limit.get("acceleration")
        if text is None:
            continue
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not value > 0.0:
            raise ValueError(f"{urdf}: joint {joint.get('name')!r}: limit acceleration must be "
                             f"a positive number, got {text!r}")
        limits[joint.get("name")] = value
    return limits


def acceleration_limits(model: pin.Model, urdf: pathlib.Path, given: Any,
                        planar_base: bool) -> np.ndarray | None:
    """The robot's (nv,) acceleration limits, read-only: ``given`` (nv values, or one for
    every joint) when given; else the URDF's ``<limit acceleration>`` (``inf`` where a
    joint has none); else the velocity limit over :data:`ACCELERATION_RAMP_TIME` (``inf``
    where a joint has no positive, finite velocity limit) and a planar base's
    :data:`ROOT_ACCELERATION_LIMIT`; None when no joint has one."""
    from controllers.joint_acceleration import as_acceleration_limit

    if given is not None:
        return _readonly(as_acceleration_limit(given, model.nv))
    from_urdf = urdf_acceleration_limits(urdf)
    limits = np.full(model.nv, np.inf)
    for joint in range(1, model.njoints):
        if model.names[joint] in from_urdf:
            start = model.idx_vs[joint]
            limits[start:start + model.nvs[joint]] = from_urdf[model.names[joint]]
    if from_urdf:
        return _readonly(limits)
    velocity = np.asarray(model.velocityLimit, dtype=float)
    limits = np.full(model.nv, np.inf)
    limited = np.isfinite(velocity) & (velocity > 0.0)
    limits[limited] = velocity[limited] / ACCELERATION_RAMP_TIME
    if planar_base:
        limits[:3] = ROOT_ACCELERATION_LIMIT
    return _readonly(limits) if np.isfinite(limits).any() else None


#: Default velocity limits of a planar root joint: (m/s, m/s, rad/s).
DEFAULT_ROOT_VELOCITY_LIMIT = (0.5, 0.5, 1.0)


def _limit_root_velocity(model: pin.Model, limit: Any) -> None:
    """Give the planar root joint (velocity indices 0-2) finite velocity limits."""
    limit = as_vector(limit, 3, "root_velocity_limit")
    if np.any(limit <= 0.0):
        raise ValueError(f"root_velocity_limit must be positive, got {limit.tolist()}")
    velocity = np.array(model.velocityLimit, dtype=float)
    velocity[:3] = limit
    model.velocityLimit = velocity


def _ee_frames(model: pin.Model, ee_frame: str | None, ee_frames: Iterable[str] | None,
               defaults: Mapping[str, Any]) -> tuple[str, ...]:
    """The end-effector frames: given, else the built-in's, else the last body frame."""
    if ee_frame is not None and ee_frames is not None:
        raise ValueError("give ee_frame or ee_frames, not both")
    if ee_frames is not None:
        if isinstance(ee_frames, (str, bytes)) or not isinstance(ee_frames, Iterable):
            raise ValueError(f"ee_frames must be a list of frame names, got {ee_frames!r}")
        frames = tuple(ee_frames)
    elif ee_frame is not None:
        frames = (ee_frame,)
    elif defaults.get("ee_frames"):
        frames = tuple(defaults["ee_frames"])
    elif defaults.get("ee_frame"):
        frames = (defaults["ee_frame"],)
    else:
        frames = (_frame_names(model)[-1],)
    if not frames:
        raise ValueError("ee_frames is empty: name at least one end-effector frame")
    if len(set(frames)) != len(frames):
        raise ValueError(f"ee_frames names a frame twice: {list(frames)}")
    return tuple(_check_frame(model, name, "ee_frame") for name in frames)


def _constrained_links(model: pin.Model, constrained_link: str | None, link_axis: Any,
                       defaults: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Each constrained link with its read-only unit axis, in order (maybe none)."""
    if constrained_link is None and link_axis is None and defaults.get("constrained_links"):
        pairs = list(defaults["constrained_links"])
    else:
        link = constrained_link if constrained_link is not None else defaults.get("constrained_link")
        axis = link_axis if link_axis is not None else defaults.get("link_axis", (0.0, 0.0, 1.0))
        pairs = [] if link is None else [(link, axis)]
    return {_check_frame(model, link, "constrained_link"): _readonly(_check_axis(axis))
            for link, axis in pairs}
