"""The inputs of placing a constraint on a robot as the robot is now.

Each constraint type the page places registers a
:class:`web.constraint_placement.ConstraintPlacement`: a tuple of :class:`PlacementField`,
one per keyword of its ``place``. The page builds its inputs from these declarations and
checks the values by field type (the few types below), so it names no constraint kind
outside the registrations (docs/design.md section 5.5).

Field types:

* ``"link"``: a link name; ``links`` says which: ``"constrained"`` (an arm's constrained
  link, the one with an instrument axis) or ``"moving"`` (any link a joint moves, the
  constrained ones first; a mobile base included).
* ``"distance"``: metres along the chosen link's instrument axis, from its joint to its
  arm's tool tip; it applies on a link with an axis.
* ``"link_point"``: a point in the chosen link's coordinates (m); it applies on a link
  without an instrument axis (where no distance can say where the point is).
* ``"direction"``: a non-zero world 3-vector, normalised before it reaches ``place``.
* ``"number"``: a finite number within ``minimum`` and ``maximum`` (inclusive, when given).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

FieldType = Literal["link", "distance", "link_point", "direction", "number"]
LinkChoice = Literal["constrained", "moving"]
FIELD_TYPES: tuple[str, ...] = ("link", "distance", "link_point", "direction", "number")


@dataclass(frozen=True)
class PlacementField:
    """One input of a constraint type's ``place`` (:mod:`web.constraint_placement`).

    Attributes
    ----------
    name : the keyword of ``place``.
    type : one of :data:`FIELD_TYPES` (the module docstring says what each holds).
    label : what the operator reads after the type's own label (``"at (m)"`` reads
        "<type label> at (m)").
    default : the value an input starts at (a tuple for a vector; None for a link: the
        first of its choices).
    minimum, maximum : inclusive bounds of a ``"number"`` (None: unbounded).
    step : an input's increment.
    hint : one line for the operator.
    links : which links a ``"link"`` field offers.
    """

    name: str
    type: FieldType
    label: str
    default: object = None
    minimum: float | None = None
    maximum: float | None = None
    step: float | None = None
    hint: str = ""
    links: LinkChoice = "constrained"

    def __post_init__(self) -> None:
        if self.type not in FIELD_TYPES:
            raise ValueError(f"placement field {self.name!r}: unknown type {self.type!r}, "
                             f"one of {', '.join(FIELD_TYPES)}")
        if self.links not in ("constrained", "moving"):
            raise ValueError(f"placement field {self.name!r}: links must be 'constrained' "
                             f"or 'moving', got {self.links!r}")


#: the constrained link (one per arm) the constraint goes on
ON_ARM = PlacementField("link", "link", "arm",
                        hint="the constrained link (one per arm) it goes on")
#: any link a joint moves: an arm's constrained link, or another (a mobile base: a wall)
ON_ANY_LINK = PlacementField("link", "link", "on link", links="moving",
                             hint="an arm's constrained link, or any other link that moves "
                                  "(a mobile base: a wall)")
#: the point at a distance along the link's instrument axis
ALONG_LINK = PlacementField("distance", "distance", "at (m)", default=0.08, step=0.005,
                            hint="distance along the constrained link")
#: the point in the link's own coordinates, on a link without an instrument axis
ON_LINK_POINT = PlacementField("link_point", "link_point", "point on link (m)",
                               default=(0.0, 0.0, 0.0), step=0.05,
                               hint="in the link's own coordinates (a link without an "
                                    "instrument axis)")
