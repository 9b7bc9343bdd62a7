"""The per-type pieces each layer registers for a constraint type (issue 34 item 4): the
plant's wall, the collision avoidance's port, the experiments' sliding and the page's
drawing, each looked up by type along its bases; a type registered nowhere gets none (or,
for the drawing, the base ``Constraint``'s grey point)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from constraints import Barrier, Constraint, Hole, Plane, PointLock
from constraints.collision.ports import is_port
from constraints.kinematics import frame_placement
from teleop.experiments.sliding import slid_along_link, sliding_axis
from teleop.plants.walls import PortWall, has_wall, wall_of
from web.constraint_drawing import constraint_geometry, drawing_of


class LongHole(Hole):
    """A hole subclass that registers nothing of its own."""


class TiltedPlane(Plane):
    """A plane subclass that registers nothing of its own."""


class Fixed(Constraint):
    """A user's own type registered nowhere: the link's origin held on the world x axis
    (``C`` the link coordinates of world y and z)."""

    dim = 2
    kind = "fixed"
    position_attribute = "anchor"

    def __init__(self, link: str, anchor=(0.0, 0.0, 0.0)) -> None:
        super().__init__(link)
        self.anchor = np.asarray(anchor, dtype=float)
        self.velocity = np.zeros(3)

    def point(self, placement: pin.SE3) -> np.ndarray:
        return np.zeros(3)

    def directions(self, placement: pin.SE3) -> np.ndarray:
        return placement.rotation[1:]

    def error(self, placement: pin.SE3) -> np.ndarray:
        return (placement.translation - self.anchor)[1:]


def samples(link: str) -> list[Constraint]:
    return [Hole(link, [0.4, 0.1, 0.9]), LongHole(link, [0.4, 0.1, 0.9]),
            Plane(link, [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 0.0, 1.0]),
            TiltedPlane(link, [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 1.0, 0.0]),
            Barrier(link, [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 0.0, 1.0]),
            PointLock(link, [0.0, 0.0, 0.1], [0.4, 0.1, 0.9]), Fixed(link)]


def test_a_hole_and_its_subclasses_are_ports_with_a_wall_and_nothing_else_is(sda10f):
    found = {type(c).__name__: (has_wall(c), is_port(c), type(wall_of(c)).__name__)
             for c in samples(sda10f.constrained_link)}
    assert found == {"Hole": (True, True, "PortWall"), "LongHole": (True, True, "PortWall"),
                     "Plane": (False, False, "NoneType"),
                     "TiltedPlane": (False, False, "NoneType"),
                     "Barrier": (False, False, "NoneType"),
                     "PointLock": (False, False, "NoneType"),
                     "Fixed": (False, False, "NoneType")}


def test_the_port_wall_by_hand():
    """A hole at (0, 0, 0.5) on a link along world z whose origin is 2 mm off in x: the
    port is (0.002, 0, 0.5); the spring -k (P - c) = (-2, 0, 0) N at k = 1000 N/m; the
    damper takes the lateral 0.1 m/s only: -10 * 0.1 = -1 N along x."""
    hole = Hole("link", [0.0, 0.0, 0.5])
    wall = PortWall()
    point, axis = wall.port(hole, np.eye(3), np.array([0.002, 0.0, 0.1]))
    np.testing.assert_allclose(point, [0.002, 0.0, 0.5], atol=1e-15)
    np.testing.assert_allclose(axis, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(wall.spring(hole, point), [-2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(wall.force(hole, point, axis, np.array([0.1, 0.0, 0.3])),
                               [-3.0, 0.0, 0.0], atol=1e-12)
    assert wall.displacement(hole, point) == pytest.approx(0.002, rel=1e-12)
    wall.set_stiffness(hole, 500.0)
    np.testing.assert_allclose(wall.spring(hole, point), [-1.0, 0.0, 0.0], atol=1e-12)


def test_a_type_registered_nowhere_does_not_slide_and_draws_as_a_grey_point(sda10f):
    q = sda10f.q_home
    fixed = Fixed(sda10f.constrained_link, [0.4, 0.1, 0.9])
    assert sliding_axis(fixed, sda10f, q) is None
    assert slid_along_link(fixed, sda10f, q, 0.01) is fixed
    placement = frame_placement(sda10f.model, q, fixed.link)
    geometry = constraint_geometry(fixed, placement)
    assert (geometry.shape, geometry.color, geometry.axis) == ("point", (128, 128, 128), None)
    # the world error R C^T e: the link origin's offset from the x axis through the anchor
    offset = placement.translation - fixed.anchor
    np.testing.assert_allclose(geometry.error, [0.0, *offset[1:]], atol=1e-12)


def test_a_subclass_slides_along_the_axis_of_its_base_and_draws_as_it(sda10f):
    q = sda10f.q_home
    link = sda10f.constrained_link
    for base, sub in ((Hole(link, [0.4, 0.1, 0.9]), LongHole(link, [0.4, 0.1, 0.9])),
                      (Plane(link, [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 0.0, 1.0]),
                       TiltedPlane(link, [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 0.0, 1.0]))):
        assert drawing_of(sub) is drawing_of(base)
        np.testing.assert_array_equal(sliding_axis(sub, sda10f, q),
                                      sliding_axis(base, sda10f, q))
