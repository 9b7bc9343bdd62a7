"""Collision avoidance: the robot's capsule geometry, obstacles, the pairs kept apart and
their velocity-damper rows (docs/design.md section 18)."""

from .avoidance import (DEFAULT_APPROACH_SPEED, DEFAULT_DETECTION_DISTANCE,
                        DEFAULT_SAFETY_DISTANCE, CollisionAvoidance)
from .obstacles import OBSTACLE_TYPES, Box, Capsule, HalfSpace, Obstacle, ObstacleGeometry, Sphere
from .rows import CollisionRows

__all__ = ["Box", "Capsule", "CollisionAvoidance", "CollisionRows", "DEFAULT_APPROACH_SPEED",
           "DEFAULT_DETECTION_DISTANCE", "DEFAULT_SAFETY_DISTANCE", "HalfSpace", "OBSTACLE_TYPES",
           "Obstacle", "ObstacleGeometry", "Sphere"]
