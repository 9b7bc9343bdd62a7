"""A sweep: a grid of ``compare`` cells (docs/sweep.md, docs/design.md section 15.7).

A spec names scenarios, controllers, seeds and every other input of a run, each either one
value or a list of values; the grid is every combination of the lists. One combination
with one controller is a :class:`Cell`: one ``teleop compare`` run, reproducible alone from
its inputs. A cell's inputs are a flat mapping of :data:`CELL_FIELDS` with the fields at
their defaults left out, so a field added later with a neutral default changes no key; its
key is the SHA-256 of their canonical JSON.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from constraints.validation import as_number, short_repr
from teleop.json_text import parse_json
from teleop.limits import MAX_CELLS, MAX_SPEC_BYTES
from teleop.options import (ACCELERATION_LIMITS_HELP, CALIBRATION_POSITION, CALIBRATION_ROTATION,
                            CONSTRAINT_GAIN, DURATION, ENCODER_NOISE, JERK_LIMIT,
                            JOINT_TIME_CONSTANT, KP, LATENCY, PATH_AMPLITUDE, RATE, SEED,
                            SIMULATED_PLANT_KINDS, TROCAR_SHIFT, SharedOption)
from teleop.plants.options import PLANT_OPTIONS_BY_NAME
from teleop.plants.settings import PlantSettings

#: The physics plant's payload, a grid field.
PAYLOAD = PLANT_OPTIONS_BY_NAME["payload"]

#: Hex digits of a cell's key (80 bits: no collision in any sweep of this world).
KEY_DIGITS = 20

#: Default wall-clock limit of one cell (s).
DEFAULT_TIME_LIMIT_S = 600.0


def _text(value: Any, name: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{name} must be a non-empty string, got {short_repr(value)}")
    return value.strip()


def _real(minimum: float | None = None, maximum: float | None = None,
          positive: bool = False) -> Callable[[Any, str], float]:
    """A checker of a finite float in range (``1`` and ``1.0`` are one value)."""
    return lambda value, name: as_number(value, name, minimum, positive=positive,
                                         maximum=maximum)


def _boolean(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {short_repr(value)}")
    return value


def _optional(check: Callable[[Any, str], Any]) -> Callable[[Any, str], Any]:
    return lambda value, name: None if value is None else check(value, name)


@dataclass(frozen=True)
class CellField:
    """One input of a cell: its name, its default (left out of the key when equal), how a
    value is checked and normalised, the ``teleop compare`` option that sets it (None: the
    command has a form of its own for it), the spec table it may be written in, and the
    option it is declared by (``declared``, :mod:`teleop.options`; None: the sweep's own)."""

    name: str
    default: Any
    check: Callable[[Any, str], Any]
    option: str | None = None
    group: str | None = None
    help: str = ""
    declared: SharedOption | None = None

    def default_words(self) -> str:
        """What leaving a declared number field out means, in words (``"1000"``)."""
        if self.default is None and self.declared is not None:
            return self.declared.left_out
        return f"{self.default:g}"


def _declared(option: SharedOption, default: Any = None, group: str | None = None,
              on_compare: bool = True) -> CellField:
    """The field of a declared option: its name, default (``option.default`` unless
    given), validator, command-line option (unless ``on_compare`` is False: compare
    writes it otherwise) and help."""
    default = option.default if default is None else default
    return CellField(option.name, default,
                     option.check if default is not None else _optional(option.check),
                     option.option if on_compare else None, group, option.help_text(), option)


def _cell_fields() -> tuple[CellField, ...]:
    """The fields; those ``teleop compare`` shares with the other front ends from their
    declaration (:class:`teleop.options.SharedOption`: the same validator and words as
    the command lines)."""
    return (
        CellField("scenario", None, _text, "--scenario", help="scenario names"),
        CellField("controller", None, _text, "--controllers", help="controller specs"),
        CellField("robot", None, _optional(_robot_choice), None,
                  help="the robot the scenarios run on (default: each scenario's own): a "
                       "table of robot (a built-in name, a URDF path or an example-robot-data "
                       "name), ee_frame, constrained_link, link_axis, locked_joints, "
                       "package_dirs, q_home, as teleop compare's options"),
        _declared(SEED),
        _declared(DURATION),
        _declared(RATE),
        CellField("plant", "kinematic", _plant_kind, "--plant", help="kinematic or mujoco"),
        CellField("acceleration_limits", True, _boolean, None, help=ACCELERATION_LIMITS_HELP),
        _declared(JERK_LIMIT),
        _declared(PAYLOAD.option, PlantSettings().payload / PAYLOAD.scale),
        _declared(KP),
        _declared(CONSTRAINT_GAIN),
        _declared(ENCODER_NOISE, group="imperfections"),
        _declared(LATENCY, group="imperfections"),
        _declared(JOINT_TIME_CONSTANT, group="imperfections"),
        _declared(CALIBRATION_POSITION, group="imperfections", on_compare=False),
        _declared(CALIBRATION_ROTATION, group="imperfections", on_compare=False),
        _declared(TROCAR_SHIFT, group="variations"),
        _declared(PATH_AMPLITUDE, group="variations"),
    )


#: The keys of a cell's ``robot`` table: (key, a list of what, its length; None: a name).
ROBOT_KEYS: dict[str, tuple[type, int | None] | None] = {
    "robot": None, "ee_frame": None, "constrained_link": None,
    "link_axis": (float, 3), "locked_joints": (str, None), "package_dirs": (str, None),
    "q_home": (float, None)}


def _robot_choice(value: Any, name: str) -> dict[str, Any]:
    """A cell's ``robot`` table checked: :data:`ROBOT_KEYS` only, names as text, lists of
    names or numbers (the options' values); keys in order."""
    if not isinstance(value, Mapping) or not value:
        raise ValueError(f"{name} must be a table of robot options, got {short_repr(value)}")
    unknown = sorted(set(value) - set(ROBOT_KEYS))
    if unknown:
        raise ValueError(f"{name}: unknown key {unknown[0]!r}; keys: {', '.join(ROBOT_KEYS)}")
    checked: dict[str, Any] = {}
    for key, kind in ROBOT_KEYS.items():
        if key not in value:
            continue
        item = value[key]
        if kind is None:
            checked[key] = _text(item, f"{name}.{key}")
            continue
        what, length = kind
        if not isinstance(item, (list, tuple)) or (length is not None and len(item) != length) \
                or not item:
            raise ValueError(f"{name}.{key} must be a list of "
                             f"{length or 'one or more'} {'numbers' if what is float else 'names'},"
                             f" got {short_repr(item)}")
        checked[key] = [as_number(v, f"{name}.{key}") if what is float else _text(v, f"{name}.{key}")
                        for v in item]
    return checked


def _plant_kind(value: Any, name: str) -> str:

    if value == "ros2":
        raise ValueError(f"{name} ros2 is one real robot and a sweep runs cells in parallel: "
                         "run 'teleop compare --plant ros2' instead (docs/ros2.md)")
    if value not in SIMULATED_PLANT_KINDS:
        raise ValueError(f"{name} must be one of {', '.join(SIMULATED_PLANT_KINDS)}, got "
                         f"{short_repr(value)}")
    return value


CELL_FIELDS: tuple[CellField, ...] = _cell_fields()
FIELDS_BY_NAME = {f.name: f for f in CELL_FIELDS}

#: The spec's own fields beside the cells' (plural names for the lists of the grid).
SPEC_KEYS = {"scenarios": "scenario", "controllers": "controller", "seeds": "seed",
             "plants": "plant"}
RUN_KEYS = ("time_limit",)
GROUPS = ("imperfections", "variations")


def cell_key(inputs: Mapping[str, Any]) -> str:
    """The key of a cell's inputs: SHA-256 of their canonical JSON, :data:`KEY_DIGITS` hex."""
    text = json.dumps(dict(inputs), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:KEY_DIGITS]


def canonical_inputs(values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` checked field by field (``ValueError`` naming it), normalised, and the
    fields at their defaults left out; ``scenario`` and ``controller`` are required."""
    unknown = sorted(set(values) - set(FIELDS_BY_NAME))
    if unknown:
        raise ValueError(f"unknown cell field {unknown[0]!r}")
    inputs = {}
    for cell_field in CELL_FIELDS:
        if cell_field.name not in values:
            if cell_field.default is None and cell_field.name in ("scenario", "controller"):
                raise ValueError(f"{cell_field.name} is required")
            continue
        value = cell_field.check(values[cell_field.name], cell_field.name)
        if value != cell_field.default or cell_field.name in ("scenario", "controller"):
            inputs[cell_field.name] = value
    return inputs


def cell_value(inputs: Mapping[str, Any], name: str) -> Any:
    """A field of a cell's inputs, its default when left out."""
    return inputs.get(name, FIELDS_BY_NAME[name].default)


@dataclass(frozen=True)
class Cell:
    """One ``compare`` run of the grid: its canonical inputs and their key."""

    inputs: dict[str, Any]
    key: str

    @classmethod
    def of(cls, values: Mapping[str, Any]) -> "Cell":
        inputs = canonical_inputs(values)
        return cls(inputs, cell_key(inputs))

    def __getitem__(self, name: str) -> Any:
        return cell_value(self.inputs, name)


@dataclass(frozen=True)
class SweepSpec:
    """A sweep: every grid field as the list of its values, and the run's own settings.

    ``grid`` maps each cell field to the values it takes (one value: a list of one);
    ``time_limit`` is each cell's wall-clock limit (s), not part of a cell's key.
    """

    grid: dict[str, list[Any]]
    time_limit: float = DEFAULT_TIME_LIMIT_S
    source: str = "the command line"
    notes: tuple[str, ...] = field(default=())

    def cells(self) -> list[Cell]:
        """Every combination of the grid, a seed's controllers side by side."""
        names = [f.name for f in CELL_FIELDS if f.name in self.grid]
        order = [n for n in names if n not in ("seed", "controller")] + ["seed", "controller"]
        combinations = itertools.product(*(self.grid[name] for name in order))
        return [Cell.of(dict(zip(order, values))) for values in combinations]

    @property
    def size(self) -> int:
        return math.prod(len(values) for values in self.grid.values())


def build_spec(document: Mapping[str, Any], source: str = "the command line") -> SweepSpec:
    """A :class:`SweepSpec` from a spec document (a TOML or JSON file's table, or the
    command line's options as one); ``ValueError`` naming the field for anything wrong:
    an unknown or missing field, a value out of range, an empty list, a value given twice,
    an unknown scenario or controller."""
    if not isinstance(document, Mapping):
        raise ValueError(f"a spec must be a table of fields, got {type(document).__name__}")
    flat: dict[str, Any] = {}
    for name, value in document.items():
        if name in GROUPS:
            if not isinstance(value, Mapping):
                raise ValueError(f"{name} must be a table, got {short_repr(value)}")
            for inner, inner_value in value.items():
                cell_field = FIELDS_BY_NAME.get(inner)
                if cell_field is None or cell_field.group != name:
                    raise ValueError(f"unknown field {name}.{inner}")
                flat[inner] = inner_value
        elif name in SPEC_KEYS or name in RUN_KEYS or name in FIELDS_BY_NAME:
            if name in ("scenario", "controller", "seed", "plant"):
                raise ValueError(f"unknown field {name!r} (did you mean {name}s?)")
            flat[name] = value
        else:
            raise ValueError(f"unknown field {name!r}")
    for required in ("scenarios", "controllers"):
        if required not in flat:
            raise ValueError(f"{required} is required")
    time_limit = _real(positive=True, maximum=86_400.0)(
        flat.pop("time_limit", DEFAULT_TIME_LIMIT_S), "time_limit")
    grid: dict[str, list[Any]] = {}
    for name, value in flat.items():
        cell_name = SPEC_KEYS.get(name, name)
        grid[cell_name] = _values(name, cell_name, value)
    grid.setdefault("seed", [0])
    _check_grid(grid)
    spec = SweepSpec(grid, time_limit, source)
    if spec.size > MAX_CELLS:
        raise ValueError(f"the grid has {spec.size} cells, more than {MAX_CELLS}")
    return SweepSpec(grid, time_limit, source, _notes(grid))


def _values(name: str, cell_name: str, value: Any) -> list[Any]:
    """One grid field's values: checked, normalised, none twice, at least one."""
    cell_field = FIELDS_BY_NAME[cell_name]
    if name == "seeds" and isinstance(value, int) and not isinstance(value, bool):
        if not 1 <= value <= MAX_CELLS:
            raise ValueError(f"seeds as a count must be in [1, {MAX_CELLS}], got {value}")
        return list(range(value))
    values = list(value) if isinstance(value, (list, tuple)) else [value]
    if not values:
        raise ValueError(f"{name} is empty: the grid would have no cell")
    checked = [cell_field.check(v, name) for v in values]
    repeated = sorted({repr(v) for v in checked if checked.count(v) > 1})
    if repeated:
        raise ValueError(f"{name} lists {repeated[0]} twice")
    return checked


def scenario_robot(scenario: str, robot: Mapping[str, Any] | None):
    """The robot a cell's ``robot`` table asks for (None: None, the scenario's own), loaded
    as ``teleop compare`` loads its robot options
    (:func:`teleop.robots.catalog.load_robot_choice`)."""
    if robot is None:
        return None
    from teleop.experiments.scenarios import SCENARIOS
    from teleop.robots.catalog import load_robot_choice

    if scenario not in SCENARIOS:
        return None  # load_scenario names the known ones
    options = dict(robot)
    return load_robot_choice(options.pop("robot", None), SCENARIOS[scenario][0], **options)


def _check_grid(grid: dict[str, list[Any]]) -> None:
    """What the cells' runs would refuse, refused before any runs: an unknown scenario or
    controller (each controller built on each scenario's robot), a payload or a
    calibration error on a plant that cannot take it, a duration of no control period or
    too many, a constraint gain unstable at a rate (docs/design.md 3.4)."""
    from teleop.controller_specs import make_controller
    from teleop.experiments.compare import check_constraint_gain
    from teleop.experiments.contact_compare import refuse_contact_scenario
    from teleop.experiments.scenarios import load_scenario
    from teleop.limits import MAX_STEPS

    plants = grid.get("plant", ["kinematic"])
    if any(grid.get("payload", [0.0])) and "kinematic" in plants:
        raise ValueError("payload needs the mujoco plant (plants lists kinematic)")
    if (any(grid.get("calibration_error_mm", [0.0]))
            or any(grid.get("calibration_error_mrad", [0.0]))) and "mujoco" in plants:
        raise ValueError("calibration error needs the kinematic plant (plants lists mujoco)")
    for scenario, robot in itertools.product(grid["scenario"], grid.get("robot", [None])):
        try:
            refuse_contact_scenario(scenario, "teleop sweep")
            plan = load_scenario(scenario, scenario_robot(scenario, robot))
        except ValueError as error:
            raise ValueError(f"scenarios: {error}") from None
        for controller in grid["controller"]:
            try:
                make_controller(controller, plan.robot, plan.make_constraints(),
                                collisions=plan.make_collisions())
            except ValueError as error:
                raise ValueError(f"controllers: {error}") from None
        for rate in grid.get("rate", [FIELDS_BY_NAME["rate"].default]):
            for duration in grid.get("duration", [None]):
                seconds = duration or plan.duration
                steps = int(round(seconds * rate))
                if not 1 <= steps <= MAX_STEPS:
                    raise ValueError(f"duration {seconds:g} s at rate {rate:g} Hz is {steps} "
                                     f"control periods, not in [1, {MAX_STEPS}] ({scenario})")
            for gain in grid.get("constraint_gain", [None]):
                if gain is not None:
                    check_constraint_gain(plan.with_constraint_gain(gain), 1.0 / rate)


def _notes(grid: dict[str, list[Any]]) -> tuple[str, ...]:
    """What a human should know before running: seeds that change nothing."""
    random = ("encoder_noise", "calibration_error_mm", "calibration_error_mrad",
              "trocar_shift", "path_amplitude")
    if len(grid["seed"]) > 1 and not any(any(v for v in grid.get(name, [0])) for name in random):
        return (f"the {len(grid['seed'])} seeds change nothing: no encoder noise, calibration "
                "error, trocar shift or path amplitude is on, so each seed's cells repeat the "
                "same run",)
    return ()


def load_spec(path: str | Path, options: Mapping[str, Any] | None = None) -> SweepSpec:
    """A spec file, TOML (``.toml``) or JSON (anything else), of at most
    :data:`~teleop.limits.MAX_SPEC_BYTES`, with the command line's ``options`` over its
    fields (:func:`merge_options`); ``ValueError`` naming the file and what is wrong."""
    path = Path(path)
    try:
        with path.open("rb") as file:
            data = file.read(MAX_SPEC_BYTES + 1)  # no further: /dev/zero has no end
        if len(data) > MAX_SPEC_BYTES:
            raise ValueError(f"{path}: a spec is at most {MAX_SPEC_BYTES} bytes, this file "
                             "is longer")
        text = data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as error:
        reason = getattr(error, "strerror", None) or error
        raise ValueError(f"{path}: cannot read the spec ({reason})") from None
    document = _parse(path, text)
    try:
        if options:
            document = merge_options(document, options)
        return build_spec(document, str(path))
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def _parse(path: Path, text: str) -> Any:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    if path.suffix.lower() == ".toml":
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise ValueError(f"{path}: not a TOML spec ({error})") from None
        except RecursionError:
            raise ValueError(f"{path}: TOML nested too deeply") from None
    return parse_json(text, str(path))


def merge_options(document: Mapping[str, Any], options: Mapping[str, Any]) -> dict[str, Any]:
    """A spec document with the command line's options over it (an option given replaces
    the file's field, in its table when it has one)."""
    merged = {name: (dict(value) if isinstance(value, Mapping) else value)
              for name, value in document.items()}
    for name, value in options.items():
        group = FIELDS_BY_NAME[name].group if name in FIELDS_BY_NAME else None
        if group is not None:
            merged.setdefault(group, {})
            if not isinstance(merged[group], dict):
                raise ValueError(f"{group} must be a table, got {short_repr(merged[group])}")
            merged[group][name] = value
        else:
            merged[name] = value
    return merged


def describe_cell(inputs: Mapping[str, Any]) -> str:
    """One line: the scenario, controller, seed and every other input not at its default."""
    rest = ", ".join(f"{name} {value}" for name, value in inputs.items()
                     if name not in ("scenario", "controller", "seed"))
    return (f"{inputs['scenario']} / {inputs['controller']} / seed {cell_value(inputs, 'seed')}"
            + (f" ({rest})" if rest else ""))
