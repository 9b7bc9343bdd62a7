"""What stands between the loop and the robot's true joints (docs/design.md sections 15.1
and 17): the imperfect kinematic robot and the MuJoCo physics plant."""

from .choice import PLANT_KINDS, PlantChoice
from .imperfect import Imperfections, ImperfectPlant
from .mujoco_plant import MujocoPlant, PlantMeasures, largest_force
from .settings import MIN_PHYSICS_RATE_HZ, PlantSettings

__all__ = ["MIN_PHYSICS_RATE_HZ", "PLANT_KINDS", "ImperfectPlant", "Imperfections",
           "MujocoPlant", "PlantChoice", "PlantMeasures", "PlantSettings", "largest_force"]
