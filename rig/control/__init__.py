"""Off-line force control of stepped multi-sine steps."""

from rig.control.force_controller import (
    ControlDecision,
    ControlSettings,
    ForceController,
    StepControlRecord,
    loop_check_gain,
)

__all__ = [
    "ControlDecision",
    "ControlSettings",
    "ForceController",
    "StepControlRecord",
    "loop_check_gain",
]
