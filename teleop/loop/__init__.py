"""The closed teleoperation loop: operator target -> EE twist -> controller -> integrate."""

from .closed_loop import (
    LoopConfig,
    Plant,
    Targets,
    TeleopLoop,
    constraint_names,
    row_labels,
    saturate_twist,
    target_poses,
)
from .distance_meter import SAFETY_TOLERANCE, DistanceMeasure, DistanceMeter
from .records import RECORD_FIELDS, CompiledPendingStep, PendingStep, StepRecord

__all__ = ["RECORD_FIELDS", "SAFETY_TOLERANCE", "CompiledPendingStep", "DistanceMeasure", "DistanceMeter", "LoopConfig", "PendingStep", "Plant", "StepRecord", "Targets", "TeleopLoop",
           "constraint_names", "row_labels", "saturate_twist", "target_poses"]
