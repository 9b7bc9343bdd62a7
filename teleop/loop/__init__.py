"""The closed teleoperation loop: operator target -> EE twist -> controller -> integrate."""

from .closed_loop import (
    RECORD_FIELDS,
    LoopConfig,
    Plant,
    StepRecord,
    Targets,
    TeleopLoop,
    constraint_names,
    row_labels,
    saturate_twist,
    target_poses,
)
from .distance_meter import SAFETY_TOLERANCE, DistanceMeasure, DistanceMeter

__all__ = ["RECORD_FIELDS", "SAFETY_TOLERANCE", "DistanceMeasure", "DistanceMeter", "LoopConfig", "Plant", "StepRecord", "Targets", "TeleopLoop",
           "constraint_names", "row_labels", "saturate_twist", "target_poses"]
