"""Why a run stops early: faults found by the checks, and aborts asked for by someone.

A :class:`RunFault` is raised by the engine's checks (limits, clipping, a silent sensor, an
amplifier overload, a stalled DAQ) or by plan code (a diverging controller, a failed pretest).
Its message is written for the operator: what happened, where, and what to do; it becomes the
measurement file's ``exit_message``. :class:`RunAborted` is a requested stop (the operator, a
signal, an abort limit).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

__all__ = [
    "FAULT_KINDS",
    "FAULT_SYNTAX",
    "RECOVERABLE",
    "SIM_FAULT_KINDS",
    "RunAborted",
    "RunFault",
    "SimFault",
    "parse_sim_fault",
    "switch_on",
]

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


# ------------------------------------------------------------------------ simulated faults
SIM_FAULT_KINDS = {
    "disconnect": "CHANNEL:disconnect  the channel's sensor is unplugged (noise floor only)",
    "clip": "CHANNEL:clip=LEVEL  the channel's sensor saturates at LEVEL (channel units)",
    "read-timeout": "read-timeout  the DAQ stops delivering samples",
    "amplifier-overload": "amplifier-overload  the power amplifier trips",
}
"""Faults of the simulated rig that ``--fault`` switches on, with their syntax."""

FAULT_SYNTAX = (
    "[CHANNEL:]KIND[=LEVEL][@stepN], e.g. acc7:disconnect@step3, acc7:clip=12, "
    "read-timeout@step2; kinds: " + ", ".join(SIM_FAULT_KINDS)
)


@dataclass(frozen=True)
class SimFault:
    """A fault of the simulated rig, switched on from a step of the run on.

    Attributes
    ----------
    kind : str
        One of :data:`SIM_FAULT_KINDS`.
    channel : str
        The channel (``disconnect``, ``clip``), else "".
    level : float or None
        The saturation level of ``clip`` [channel units].
    from_step : int
        The fault acts from this step of the run on (1: from the start).
    """

    kind: str
    channel: str = ""
    level: float | None = None
    from_step: int = 1


_FAULT_RE = re.compile(
    r"^(?:(?P<channel>[^:@=\s]+):)?(?P<kind>[a-z-]+)(?:=(?P<level>[^@\s]+))?"
    r"(?:@step(?P<step>\d+))?$"
)


def parse_sim_fault(text: str) -> SimFault:
    """Parse a ``--fault`` argument (see :data:`FAULT_SYNTAX`).

    Raises
    ------
    ValueError
        Saying what is wrong with ``text`` and giving the syntax.
    """

    def bad(problem: str) -> ValueError:
        return ValueError(f"--fault {text!r}: {problem}; expected {FAULT_SYNTAX}")

    m = _FAULT_RE.match(text.strip()) if isinstance(text, str) else None
    if m is None:
        if isinstance(text, str) and "@" in text and not re.search(r"@step\d+$", text):
            raise bad("the step is written @stepN, N = 1, 2, ...")
        raise bad("not understood")
    kind, channel, level_text, step = m["kind"], m["channel"] or "", m["level"], m["step"]
    if kind not in SIM_FAULT_KINDS:
        raise bad(f"unknown fault {kind!r}")
    needs_channel = kind in ("disconnect", "clip")
    if needs_channel and not channel:
        raise bad(f"{kind!r} needs a channel (CHANNEL:{kind})")
    if not needs_channel and channel:
        raise bad(f"{kind!r} concerns the whole rig, not a channel")
    level = None
    if kind == "clip":
        if level_text is None:
            raise bad("clip needs a level: CHANNEL:clip=LEVEL")
        try:
            level = float(level_text)
        except ValueError:
            raise bad(f"the level {level_text!r} is not a number") from None
        if not (math.isfinite(level) and level > 0):
            raise bad(f"the level must be a number > 0, got {level_text}")
    elif level_text is not None:
        raise bad(f"{kind!r} takes no level")
    from_step = 1 if step is None else int(step)
    if from_step < 1:
        raise bad("steps are counted from 1 (@step1 is the start)")
    return SimFault(kind, channel, level, from_step)


def switch_on(switches: Any, faults: Iterable[SimFault]) -> Any:
    """``switches`` (the simulated DAQ's fault switches) with ``faults`` switched on too."""
    disconnected = list(switches.disconnected)
    clip = dict(switches.clip_levels)
    changes: dict[str, Any] = {}
    for f in faults:
        if f.kind == "disconnect" and f.channel not in disconnected:
            disconnected.append(f.channel)
        elif f.kind == "clip":
            clip[f.channel] = f.level
        elif f.kind == "read-timeout":
            changes["read_timeout"] = True
        elif f.kind == "amplifier-overload":
            changes["amplifier_overload"] = True
    return dataclasses.replace(
        switches, disconnected=tuple(disconnected), clip_levels=clip, **changes
    )
