"""How the simulated robot is built and driven (docs/design.md section 17.1)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from constraints.validation import as_number
from teleop.limits import MAX_JOINT_FRICTION, MIN_PHYSICS_RATE_HZ

from .options import holder_options


#: :meth:`PlantSettings.to_dict`'s keys (units in the names) -> the settings' fields.
SETTINGS_KEYS = {"physics_rate_hz": "physics_rate", "servo_bandwidth_hz": "servo_bandwidth",
                 "servo_damping_ratio": "servo_damping_ratio", "armature_kg_m2": "armature",
                 "joint_damping_nms": "joint_damping", "payload_kg": "payload",
                 "coulomb_friction_nm": "coulomb_friction",
                 "viscous_friction_nms": "viscous_friction", "gravity": "gravity",
                 "interface_limits": "interface_limits",
                 "interface_jerk_limit_radps3": "interface_jerk_limit"}


@dataclass(frozen=True)
class PlantSettings:
    """The physics plant's body and servos (docs/design.md section 17.1).

    Attributes
    ----------
    physics_rate : physics steps per second (Hz); at least :data:`MIN_PHYSICS_RATE_HZ` and
        twice the control rate; a control period runs ``ceil(physics_rate dt)`` steps.
    servo_bandwidth : natural frequency of each joint's position servo (Hz): the servo's
        gains are ``kp = I w^2``, ``kd = 2 zeta I w`` with ``w = 2 pi bandwidth`` and ``I``
        the joint's diagonal inertia (armature included) at the start configuration.
    servo_damping_ratio : ``zeta`` of the servos (1: critically damped).
    armature : reflected rotor inertia (kg m^2; kg on a prismatic joint) of every joint
        whose URDF gives none (``drake:rotor_inertia`` and ``drake:gear_ratio``,
        :func:`teleop.plants.armature.urdf_armatures`).
    joint_damping : viscous damping of every joint the servo does not know of (N m s/rad).
    payload : mass (kg) carried at each end effector, unknown to the gravity compensation
        and the controllers.
    coulomb_friction : dry friction torque of every joint (N m), unknown to the servos.
    viscous_friction : extra viscous friction of every joint (N m s/rad), unknown too.
    gravity : gravity on (the servos compensate the modelled robot's, not the payload's).
    interface_limits : the velocity interface's check of each command against the robot's
        acceleration limits and :attr:`interface_jerk_limit` (docs/design.md section 17.1,
        :mod:`teleop.plants.interface`): ``off`` (the default), ``count`` (counted, the
        robot not stopped) or ``strict`` (the first fault stops the robot, as a Franka's
        reflex does).
    interface_jerk_limit : the interface's jerk limit of every joint (rad/s^3; m/s^3 on a
        prismatic or base joint), None: no jerk limit.
    """

    physics_rate: float = MIN_PHYSICS_RATE_HZ
    servo_bandwidth: float = 20.0
    servo_damping_ratio: float = 1.0
    armature: float = 0.1
    joint_damping: float = 1.0
    payload: float = 0.0
    coulomb_friction: float = 0.0
    viscous_friction: float = 0.0
    gravity: bool = True
    interface_limits: str = "off"
    interface_jerk_limit: float | None = None

    def __post_init__(self) -> None:
        """Every field a finite number in its range (``ValueError`` naming it); the fields
        a command line sets checked by their option's one validator
        (:data:`teleop.plants.options.PLANT_OPTIONS`), the others here."""
        for option in holder_options("physics"):
            value = getattr(self, option.field)
            if value is not None or getattr(PlantSettings, option.field) is not None:
                option.option.check(value, option.field)
        as_number(self.servo_damping_ratio, "servo_damping_ratio", positive=True, maximum=10.0)
        as_number(self.armature, "armature", positive=True, maximum=1e3)
        as_number(self.joint_damping, "joint_damping", 0.0, maximum=MAX_JOINT_FRICTION)
        if not isinstance(self.gravity, bool):
            raise ValueError(f"gravity must be True or False, got {self.gravity!r}")
        if self.interface_jerk_limit is not None:
            if self.interface_limits == "off":
                raise ValueError("interface_jerk_limit needs interface_limits count or strict "
                                 "(interface_limits is off)")

    @property
    def response_time(self) -> float:
        """How late the servos follow a command (s): their time constant ``1 / w``, ``w = 2
        pi servo_bandwidth`` (what the collision damper counts on, docs/design.md 18.6)."""
        return 1.0 / (2.0 * math.pi * self.servo_bandwidth)

    def substeps(self, dt: float) -> int:
        """Physics steps per control period ``dt``: at least two."""
        return max(2, math.ceil(self.physics_rate * dt - 1e-9))

    def to_dict(self) -> dict[str, float | bool | str | None]:
        """The ``settings`` of a plant in metrics.json and session headers (units in the
        key names, :data:`SETTINGS_KEYS`)."""
        return {key: getattr(self, name) for key, name in SETTINGS_KEYS.items()}

    @classmethod
    def from_dict(cls, data: dict) -> "PlantSettings":
        """The inverse of :meth:`to_dict`, keys left out at their defaults (``KeyError`` for
        a key not in :data:`SETTINGS_KEYS`: the caller checks them and says where;
        ``ValueError`` naming a bad value)."""
        return cls(**{SETTINGS_KEYS[key]: value for key, value in data.items()})

    def changed(self) -> list[str]:
        """The :meth:`to_dict` keys whose values differ from the defaults."""
        default = PlantSettings()
        return [key for key, name in SETTINGS_KEYS.items()
                if getattr(self, name) != getattr(default, name)]

    def describe(self) -> str:
        """One line for humans."""
        extras = [f"payload {self.payload:g} kg"] if self.payload else []
        if self.coulomb_friction or self.viscous_friction:
            extras.append(f"friction {self.coulomb_friction:g} N m + "
                          f"{self.viscous_friction:g} N m s/rad")
        if self.interface_limits != "off":
            jerk = ("" if self.interface_jerk_limit is None
                    else f", jerk {self.interface_jerk_limit:g} rad/s^3")
            extras.append(f"interface limits {self.interface_limits}{jerk}")
        return (f"MuJoCo plant at {self.physics_rate:g} Hz, {self.servo_bandwidth:g} Hz servos"
                + "".join(", " + extra for extra in extras))
