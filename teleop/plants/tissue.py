"""Tissue the tool tip can touch: a compliant plane in the physics plant (docs/design.md
section 21.1).

The surface is the plane through ``point`` with outward unit ``normal``. A tip below it by
the penetration ``d = max(0, (point - p) . normal)`` is pushed out along the normal with a
one-sided Kelvin-Voigt force

    f = max(0, k d - c (v . normal)) normal,

(no pull: the damper cannot hold the tip in the tissue), and no friction: sliding along
the surface meets no resistance. The default stiffness is a flat 5 mm instrument's
(radius ``a = 2.5 mm``) on an elastic half-space (the rigid flat punch of Harding and
Sneddon 1945, ``k = 2 a E / (1 - nu^2)``) of soft organ tissue, ``E = 10 kPa``,
``nu = 0.5``, so ``k = 66.7 N/m``: about twice healthy liver's quasi-static
``E = 3 G = 5.4 kPa`` (``G = 1.8 kPa``), well below diseased liver's 60 kPa (the sources
in docs/design.md section 21.1); the damping is a chosen value (tissue's viscous time
``c / k`` of 7.5 ms), not a measured one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from constraints.limits import MAX_POSITION_M, MAX_TISSUE_DAMPING, MAX_TISSUE_STIFFNESS
from constraints.validation import as_number, as_vector, short_repr

#: Sneddon's flat punch of radius 2.5 mm on E = 10 kPa, nu = 0.5 (N/m): the module's note.
DEFAULT_TISSUE_STIFFNESS = 2.0 * 2.5e-3 * 10e3 / (1.0 - 0.5 ** 2)
#: Chosen: a viscous time c / k of 7.5 ms (N s/m).
DEFAULT_TISSUE_DAMPING = 0.5


@dataclass(frozen=True)
class TissueSurface:
    """A compliant plane the tool tip can press (docs/design.md section 21.1).

    Attributes
    ----------
    point : (3,) a point of the undeformed surface, world frame (m).
    normal : (3,) its outward normal (normalized here; refused if zero or not finite).
    stiffness : ``k`` (N/m), positive.
    damping : ``c`` (N s/m), non-negative.
    """

    point: np.ndarray
    normal: np.ndarray
    stiffness: float = DEFAULT_TISSUE_STIFFNESS
    damping: float = DEFAULT_TISSUE_DAMPING
    name: str = field(default="tissue")

    def __post_init__(self) -> None:
        point = np.asarray(self.point, dtype=float)
        normal = np.asarray(self.normal, dtype=float)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise ValueError(f"tissue {self.name!r}: point must be 3 finite numbers, got "
                             f"{self.point!r}")
        # scaled by its largest component first: the norm of a finite normal cannot overflow
        scale = (float(np.max(np.abs(normal))) if normal.shape == (3,) else float("nan"))
        if not np.isfinite(scale) or scale < 1e-9:
            raise ValueError(f"tissue {self.name!r}: normal must be 3 finite numbers, not "
                             f"zero, got {self.normal!r}")
        normal = normal / scale
        length = float(np.linalg.norm(normal))
        stiffness = as_number(self.stiffness, f"tissue {self.name!r} stiffness")
        damping = as_number(self.damping, f"tissue {self.name!r} damping")
        if not stiffness > 0.0:
            raise ValueError(f"tissue {self.name!r}: stiffness must be positive (N/m), got "
                             f"{stiffness}")
        if not damping >= 0.0:
            raise ValueError(f"tissue {self.name!r}: damping must be non-negative (N s/m), "
                             f"got {damping}")
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", normal / length)
        object.__setattr__(self, "stiffness", stiffness)
        object.__setattr__(self, "damping", damping)

    def penetration(self, tip: np.ndarray) -> float:
        """``max(0, (point - tip) . normal)`` (m)."""
        return max(0.0, float((self.point - tip) @ self.normal))

    def force(self, tip: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """The surface's force on a tip at ``tip`` moving at ``velocity`` (N, world frame)."""
        depth = self.penetration(tip)
        if depth <= 0.0:
            return np.zeros(3)
        magnitude = self.stiffness * depth - self.damping * float(velocity @ self.normal)
        return max(0.0, magnitude) * self.normal

    def to_dict(self) -> dict:
        """The surface as a JSON-ready dict (:meth:`from_dict` reads it back)."""
        return {"point": [float(x) for x in self.point],
                "normal": [float(x) for x in self.normal],
                "stiffness": float(self.stiffness), "damping": float(self.damping)}

    @classmethod
    def from_dict(cls, data: object, where: str = "tissue") -> "TissueSurface":
        """A surface from :meth:`to_dict`'s fields, each checked against the one table of
        limits (``teleop.limits``); ``ValueError`` naming the field (``where``) otherwise."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{where} must be an object with point, normal, stiffness and "
                             f"damping, got {short_repr(data)}")
        unknown = sorted(set(data) - TISSUE_FIELDS)
        if unknown:
            raise ValueError(f"unknown {where} field {unknown[0]!r} (its fields: "
                             f"{', '.join(sorted(TISSUE_FIELDS))})")
        point = as_vector(data.get("point"), 3, f"{where}.point", maximum=MAX_POSITION_M)
        normal = as_vector(data.get("normal"), 3, f"{where}.normal")
        if float(np.max(np.abs(normal))) < 1e-9:
            raise ValueError(f"{where}.normal must be a direction, not zero, got "
                             f"{normal.tolist()}")
        return cls(point, normal,
                   as_number(data.get("stiffness", DEFAULT_TISSUE_STIFFNESS),
                             f"{where}.stiffness", positive=True, maximum=MAX_TISSUE_STIFFNESS),
                   as_number(data.get("damping", DEFAULT_TISSUE_DAMPING), f"{where}.damping",
                             0.0, maximum=MAX_TISSUE_DAMPING))


#: the keys of :meth:`TissueSurface.to_dict`
TISSUE_FIELDS = frozenset({"point", "normal", "stiffness", "damping"})
