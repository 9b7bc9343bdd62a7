"""The closed teleoperation loop: operator target -> EE twist -> controller -> integrate."""

from .closed_loop import (
    RECORD_FIELDS,
    LoopConfig,
    Plant,
    StepRecord,
    TeleopLoop,
    row_labels,
    saturate_twist,
)

__all__ = ["RECORD_FIELDS", "LoopConfig", "Plant", "StepRecord", "TeleopLoop", "row_labels",
           "saturate_twist"]
