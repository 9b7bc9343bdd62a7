"""The closed teleoperation loop: operator target -> EE twist -> controller -> integrate."""

from .closed_loop import TeleopLoop
from .distance_meter import SAFETY_TOLERANCE, DistanceMeasure, DistanceMeter
from .loop_config import LoopConfig
from .measured_later import Geometry, MeasuredLater
from .naming import constraint_names, row_labels
from .plant import Plant
from .pose_servo import PoseServo, ServoPeriod
from .records import RECORD_FIELDS, CompiledPendingStep, PendingStep, StepRecord
from .state_observer import StateObserver, StateObserverConfig
from .supervisor import Supervision, Supervisor, SupervisorConfig
from .targets import Targets, saturate_twist, target_poses

__all__ = ["RECORD_FIELDS", "SAFETY_TOLERANCE", "CompiledPendingStep", "DistanceMeasure",
           "DistanceMeter", "Geometry", "LoopConfig", "MeasuredLater", "PendingStep", "Plant",
           "PoseServo", "ServoPeriod", "StateObserver", "StateObserverConfig", "StepRecord", "Supervision",
           "Supervisor", "SupervisorConfig", "Targets", "TeleopLoop", "constraint_names",
           "row_labels", "saturate_twist", "target_poses"]
