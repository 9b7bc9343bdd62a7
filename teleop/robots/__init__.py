"""Robot models: the built-in URDFs (the paper's SDA10F arm, a UR5 with an instrument),
any URDF from disk (with a home inside its limits, away from singularities), and generated
serial chains for benchmarks."""

from .home import HomeWarning
from .robot import BUILTIN_ROBOTS, Robot, load_robot

__all__ = ["BUILTIN_ROBOTS", "HomeWarning", "Robot", "load_robot"]
