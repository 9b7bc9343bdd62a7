"""Which robot a run's loop drives (docs/design.md section 17): the ideal integrator
``q += qd dt`` (``kinematic``), the MuJoCo physics plant (``mujoco``) with its settings or
a robot over ROS 2 (``ros2``, docs/ros2.md) with its topics, and the abdominal wall's
stiffness at every hole.

One :class:`PlantChoice` is the same for every controller of a comparison (and every loop
of a UI session); each run or loop builds its own plant from it (:meth:`PlantChoice.make`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping, Sequence

from constraints import Constraint
from constraints.validation import as_number, short_repr
from teleop.limits import MAX_WALL_STIFFNESS
from teleop.options import PLANT_KINDS

from .imperfect import Imperfections
from .mujoco_plant import MujocoPlant
from .options import PLANT, PLANT_OPTIONS, PLANT_OPTIONS_BY_NAME
from .ros2.settings import Ros2Settings
from .settings import SETTINGS_KEYS, PlantSettings
from .walls import wall_of


def _option(name: str) -> str:
    """A plant option as a command line spells it (``--payload``)."""
    return "--" + name.replace("_", "-")


@dataclass(frozen=True)
class PlantChoice:
    """The plant under every run of a comparison.

    Attributes
    ----------
    kind : ``kinematic`` (the ideal integrator, imperfections on top when asked) or
        ``mujoco`` (:class:`teleop.plants.MujocoPlant`, imperfections on top) or ``ros2``
        (:class:`teleop.plants.ros2.Ros2Plant`: a robot on the wire, no imperfections).
    settings : the physics plant's (:class:`PlantSettings`); the kinematic plant takes
        only the defaults (it has no body to carry a payload or feel friction).
    wall_stiffness : lateral stiffness (N/m) given to every hole's abdominal wall
        (``Hole.tissue_stiffness``); None: each hole keeps its own (1 N/mm by default).
    """

    kind: str = "kinematic"
    settings: PlantSettings = field(default_factory=PlantSettings)
    wall_stiffness: float | None = None
    ros2: Ros2Settings | None = None

    def __post_init__(self) -> None:
        """``ValueError`` naming the field: an unknown kind, settings that are not
        :class:`PlantSettings`, physics settings for the kinematic plant, a stiffness that is
        not a finite number in [0, :data:`~teleop.limits.MAX_WALL_STIFFNESS`]."""
        if self.kind not in PLANT_KINDS:
            raise ValueError(f"plant must be one of {', '.join(PLANT_KINDS)}, got "
                             f"{short_repr(self.kind)}")
        if not isinstance(self.settings, PlantSettings):
            raise ValueError(f"plant settings must be PlantSettings, got "
                             f"{type(self.settings).__name__}")
        if self.kind != "mujoco" and self.settings != PlantSettings():
            raise ValueError(f"{', '.join(self.settings.changed())} need the mujoco plant "
                             f"(plant is {self.kind})")
        if self.ros2 is not None and (self.kind != "ros2"
                                      or not isinstance(self.ros2, Ros2Settings)):
            raise ValueError(f"ros2 settings need the ros2 plant and Ros2Settings (plant is "
                             f"{self.kind}, settings {type(self.ros2).__name__})")
        if self.wall_stiffness is not None:
            object.__setattr__(self, "wall_stiffness",
                               as_number(self.wall_stiffness, "wall_stiffness", 0.0,
                                         maximum=MAX_WALL_STIFFNESS))

    @classmethod
    def with_options(cls, values: Mapping[str, Any], kind: str | None = None,
                     base: "PlantChoice | None" = None,
                     spell: Callable[[str], str] = _option) -> "PlantChoice":
        """The plant ``kind`` (None: ``base``'s) with the plant options ``values`` (name ->
        value, :data:`~teleop.plants.options.PLANT_OPTIONS`) over ``base`` (None: the
        defaults): each value checked by its option's one validator, each replacing
        ``base``'s field; a plant of another kind than ``base`` starts from its own
        defaults (``--plant kinematic`` drops a session's physics). ``ValueError`` for an
        unknown option, a bad value, or an option the plant does not take, named as
        ``spell`` writes it (``--payload needs --plant mujoco``)."""
        base = base or cls()
        kind = base.kind if kind is None else PLANT.check(kind, spell("plant"))
        unknown = sorted(set(values) - set(PLANT_OPTIONS_BY_NAME))
        if unknown:
            raise ValueError(f"unknown plant option {spell(unknown[0])}")
        given = [option for option in PLANT_OPTIONS if option.name in values]
        refused: dict[tuple[str, ...], list[str]] = {}
        for option in given:
            if kind not in option.plants:
                refused.setdefault(option.plants, []).append(spell(option.name))
        if refused:
            raise ValueError("; ".join(
                f"{', '.join(names)} need{'s' * (len(names) == 1)} {spell('plant')} "
                f"{' or '.join(plants)}" for plants, names in refused.items()))
        fields: dict[str, dict[str, Any]] = {"plant": {}, "physics": {}, "ros2": {}}
        for option in given:
            value = option.option.check(values[option.name], spell(option.name))
            fields[option.holder][option.field] = (
                value if option.scale == 1.0 else value * option.scale)
        physics = base.settings if kind == base.kind else PlantSettings()
        ros2 = (base.ros2 if kind == base.kind and base.ros2 is not None else Ros2Settings())
        return cls(kind, replace(physics, **fields["physics"]),
                   fields["plant"].get("wall_stiffness", base.wall_stiffness),
                   replace(ros2, **fields["ros2"]) if kind == "ros2" else None)

    @property
    def physical(self) -> bool:
        """A plant with a body: port forces, torques and saturation are measured."""
        return self.kind == "mujoco"

    @property
    def response_time(self) -> float:
        """How late the robot follows a command (s), what the collision damper counts on
        (docs/design.md 18.6): the physics plant's servos' time constant
        (:attr:`PlantSettings.response_time`), a robot over ROS 2's as its settings say
        (:attr:`Ros2Settings.response_time`, ``--response-time``); 0 for the kinematic
        plant (as commanded, its imperfections aside)."""
        if self.kind == "ros2":
            return (self.ros2 or Ros2Settings()).response_time
        return self.settings.response_time if self.physical else 0.0

    def make(self, robot, dt: float, imperfections: Imperfections | None = None,
             collisions=None):
        """A fresh plant for one run (a ``teleop.loop.Plant``), or None for the perfect
        kinematic robot; the physics plant simulates the contacts of ``collisions`` (a
        ``CollisionAvoidance`` of its own, or None)."""
        imperfections = imperfections or Imperfections()
        if self.kind == "ros2":
            if not imperfections.perfect:
                raise ValueError("imperfections are simulated: the ros2 plant is a real robot")
            try:  # the DDS library only when asked for
                from .ros2.ros2_plant import Ros2Plant
            except ImportError as error:
                raise ValueError(f"the ros2 plant needs the ros2 extra (pip install "
                                 f"'.[ros2]'): {error}") from None
            return Ros2Plant(robot, dt, self.ros2)
        if self.kind == "kinematic":
            return None if imperfections.perfect else imperfections.plant(robot.model, dt)
        imperfections.check_period(dt)
        return MujocoPlant(robot, dt, self.settings, imperfections, collisions)

    def apply_wall(self, constraints: Sequence[Constraint]) -> None:
        """Give every constraint with a wall (a hole's port) :attr:`wall_stiffness`."""
        if self.wall_stiffness is None:
            return
        for constraint in constraints:
            wall = wall_of(constraint)
            if wall is not None:
                wall.set_stiffness(constraint, self.wall_stiffness)

    def to_dict(self) -> dict:
        """The ``plant`` entry of metrics.json and of a session header (units in the keys):
        the kind, the physics settings (None for the kinematic plant) and the stiffness."""
        entry = {"kind": self.kind,
                 "settings": self.settings.to_dict() if self.physical else None,
                 "wall_stiffness_n_per_m": self.wall_stiffness}
        if self.kind == "ros2":
            entry["ros2"] = (self.ros2 or Ros2Settings()).to_dict()
        return entry

    @classmethod
    def from_dict(cls, data: object, where: str = "plant") -> "PlantChoice":
        """The inverse of :meth:`to_dict` (``ValueError`` naming ``where`` and the field)."""
        if not isinstance(data, dict):
            raise ValueError(f"{where} must be an object, got {short_repr(data)}")
        unknown = sorted(set(data) - {"kind", "settings", "wall_stiffness_n_per_m", "ros2"})
        if unknown:
            raise ValueError(f"{where} has unknown fields {unknown}")
        settings = data.get("settings")
        if settings is None:
            settings = {}
        if not isinstance(settings, dict):
            raise ValueError(f"{where} 'settings' must be an object, got {short_repr(settings)}")
        unknown = sorted(set(settings) - set(SETTINGS_KEYS))
        if unknown:
            raise ValueError(f"{where} 'settings' has unknown fields {unknown}")
        try:
            ros2 = data.get("ros2")
            return cls(kind=data.get("kind", "kinematic"),
                       settings=PlantSettings.from_dict(settings),
                       wall_stiffness=data.get("wall_stiffness_n_per_m"),
                       ros2=None if ros2 is None else Ros2Settings.from_dict(ros2))
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None

    def describe(self) -> str:
        """One line for humans."""
        wall = ("" if self.wall_stiffness is None
                else f", abdominal wall {self.wall_stiffness / 1000.0:g} N/mm")
        if self.kind == "ros2":
            return (self.ros2 or Ros2Settings()).describe() + wall
        if not self.physical:
            return "kinematic plant (q += qd dt)" + wall
        return self.settings.describe() + wall
