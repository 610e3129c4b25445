"""What a measurement file says about how its run ended, in words for the user.

A file is written step by step while its run goes on (``exit_status = "running"``) and closed
with ``"success"``, ``"aborted"`` or ``"failed"`` and a message saying why. A file still
``"running"`` was being written when it was read, or its process ended without closing it
(killed, or the machine stopped). An analysis of such a file is an analysis of the steps it
holds, not of the plan: :func:`incomplete_note` says what is missing, and
:func:`require_steps` refuses a file with no steps at all (a run that ended in its pretest)
with the file's name and the reason it ended.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .data import RunData, SteppedSineData

__all__ = ["incomplete_note", "input_notes", "planned_steps", "require_steps", "status_text"]

_SWEEPS = {"up": 1, "down": 1, "up-down": 2, "down-up": 2}


def planned_steps(data: RunData) -> int | None:
    """Steps the run's plan holds (from the plan stored in the file), None if not known.

    The plan's steps are every level, every sweep of its direction, every frequency of the
    union of its ranges (frequencies within 1e-6 Hz counted once), as the rig runs them.
    """
    if not isinstance(data, SteppedSineData):
        return None
    plan: Any = data.config.get("plan") if isinstance(data.config, dict) else None
    try:
        freq = plan["frequencies"]
        sweeps = _SWEEPS[freq.get("direction", "up")]
        values = []
        for r in freq["ranges"]:
            start, stop, step = float(r["start_hz"]), float(r["stop_hz"]), float(r["step_hz"])
            if not (math.isfinite(start) and math.isfinite(stop) and step > 0):
                return None
            n = round((stop - start) / step)
            values.append(np.round(start + step * np.arange(n + 1), 6))
        n_levels = len(plan["excitation"]["levels_n"])
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    if not values:
        return None
    return n_levels * sweeps * int(np.unique(np.concatenate(values)).size)


def status_text(data: RunData) -> str:
    """How the run ended: ``status 'aborted' (pretest: ...)``; for ``running``, what that means."""
    if data.exit_status == "running":
        return (
            "status 'running': the run was still under way when the file was read, or its "
            "process ended without closing the file (killed, or the machine stopped)"
        )
    why = f" ({data.exit_message})" if data.exit_message else " (no reason recorded)"
    return f"status {data.exit_status!r}{why}"


def _steps_text(data: SteppedSineData) -> str:
    planned = planned_steps(data)
    if planned is None:
        return f"{data.n_steps} steps recorded (the number planned is not recorded)"
    return f"{data.n_steps} of {planned} planned steps recorded"


def incomplete_note(data: RunData) -> str | None:
    """A note for an analysis of a run that did not end normally; None for a complete run.

    Names the file, the steps recorded against the steps planned (a stepped-sine run) and the
    status with the reason the run ended.
    """
    if data.complete and data.exit_status == "success":
        return None
    if isinstance(data, SteppedSineData):
        return (
            f"{data.path}: an incomplete run, {_steps_text(data)}; {status_text(data)}. "
            "The analysis uses the recorded steps only"
        )
    return f"{data.path}: the run did not end normally; {status_text(data)}"


def require_steps(data: SteppedSineData) -> SteppedSineData:
    """``data`` if it holds a step; otherwise a ValueError naming the file and why it ended.

    Raises
    ------
    ValueError
        ``RUN.h5 holds no steps (0 of 224 planned steps recorded); status 'aborted' (...)``.
    """
    if data.n_steps == 0:
        raise ValueError(
            f"{data.path} holds no steps ({_steps_text(data)}); {status_text(data)}: "
            "there is nothing to analyse"
        )
    return data


def input_notes(paths) -> list[str]:
    """:func:`incomplete_note` of each measurement file in ``paths`` that has one.

    For a command line, before it analyses its input files. Files that cannot be read are
    skipped (the command's own reading says why), and so are stepped-sine files with no steps
    (the command refuses them with :func:`require_steps`).
    """
    from .reader import read_measurement

    notes = []
    for path in dict.fromkeys(str(p) for p in paths if p):
        try:
            data = read_measurement(path)
        except Exception:  # noqa: BLE001 - the command reports an unreadable file itself
            continue
        if isinstance(data, SteppedSineData) and data.n_steps == 0:
            continue
        note = incomplete_note(data)
        if note:
            notes.append(note)
    return notes
