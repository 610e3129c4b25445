"""Why a run stops early: faults found by the checks, and aborts asked for by someone.

A :class:`RunFault` is raised by the engine's checks (limits, clipping, a silent sensor, an
amplifier overload, a stalled DAQ) or by plan code (a diverging controller, a failed pretest).
Its message is written for the operator: what happened, where, and what to do; it becomes the
measurement file's ``exit_message``. :class:`RunAborted` is a requested stop (the operator, a
signal, an abort limit).
"""

from __future__ import annotations

__all__ = ["FAULT_KINDS", "RECOVERABLE", "RunAborted", "RunFault"]

FAULT_KINDS = (
    "response-limit",  # an abort limit of a channel was exceeded
    "drive-limit",  # the drive needed to reach the target exceeds the plan's drive limit
    "clipping",  # a channel reached its input range, or its sensor saturated
    "sensor",  # a sensor stopped responding (open circuit, flat signal)
    "no-force",  # no force at the drive point (amplifier off or tripped, shaker loose)
    "amplifier-overload",  # the power amplifier reported an overload
    "daq",  # the DAQ failed or stopped delivering samples
    "control-diverged",  # force control diverged
    "pretest",  # the pretest found a problem
)

RECOVERABLE = frozenset({"clipping", "sensor", "no-force", "amplifier-overload"})
"""Faults an operator can fix on the bench; with ``pause_on_fault`` the run pauses on them."""


class RunFault(Exception):
    """A fault that ends (or pauses) a run.

    Parameters
    ----------
    kind : str
        One of :data:`FAULT_KINDS`.
    message : str
        What happened, in words, for the operator and the file's ``exit_message``.
    channel : str
        Channel concerned, if any.
    """

    def __init__(self, kind: str, message: str, channel: str = "") -> None:
        if kind not in FAULT_KINDS:
            raise ValueError(f"RunFault.kind: expected one of {FAULT_KINDS}, got {kind!r}")
        super().__init__(message)
        self.kind = kind
        self.message = message
        self.channel = channel

    @property
    def recoverable(self) -> bool:
        """Whether pausing (rather than ending) the run makes sense."""
        return self.kind in RECOVERABLE


class RunAborted(Exception):
    """The run was asked to stop (``reason`` says by whom and why)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason
