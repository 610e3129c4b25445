"""Progress of long work: what is being done, how far it is and the time left.

A long stage (the Latin hypercube starts of a calibration, its cross-validation folds, the steps
of a stepped-sine run) reports :class:`Progress` to a :class:`ProgressReporter`, which shows it
one of two ways:

- ``"text"``, for a person: ``calibration: Latin hypercube starts 37/100 [#######.....] 41 s,
  about 1 min 10 s left``, rewritten in place on a terminal, otherwise a line at most every
  ``interval_s`` seconds and at the end;
- ``"json"``, for a program reading the stream (``--json`` on the command line): one line per
  update, ``progress: {"stage": ..., "done": ..., "total": ..., "elapsed_s": ..., "note":
  ...}``, at most one a second per stage, and at the end. ``rig workflow`` reads these from the
  commands it runs (:func:`parse_line`) and shows them as text.

The time left is the pace so far times the work left (:func:`time_left`): the stages report
units of about equal cost.

A reporter's :meth:`ProgressReporter.event` is a listener of :mod:`analysis.events`: pass it as
the ``progress`` of a calibration, a cross-validation or a diagnosis.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from typing import TextIO

from analysis.events import Event, Iteration, StageDone, UnitDone

__all__ = [
    "PREFIX",
    "Progress",
    "ProgressReporter",
    "format_duration",
    "parse_line",
    "time_left",
]

#: What starts a progress line in ``"json"`` mode.
PREFIX = "progress: "
_JSON_INTERVAL_S = 1.0


@dataclass(frozen=True)
class Progress:
    """How far one stage is.

    Parameters
    ----------
    stage : str
        What is being done, e.g. ``"Latin hypercube starts"``.
    done : int
        Units finished.
    total : int or None
        Units in all; None when not known beforehand (an optimiser's iterations).
    elapsed_s : float
        Seconds since the stage started.
    note : str
        A detail of the last unit (``"metric 1.83"``).
    left_s : float or None
        Seconds left at the pace so far (:func:`time_left`); None when not known.
    """

    stage: str
    done: int
    total: int | None
    elapsed_s: float
    note: str = ""
    left_s: float | None = None

    @property
    def finished(self) -> bool:
        return self.total is not None and self.done >= self.total

    def text(self) -> str:
        """One line for a person."""
        count = (
            f"{self.done}/{self.total} {_bar(self.done, self.total)}"
            if self.total
            else (f"{self.done}")
        )
        left = self.left_s
        when = f"{format_duration(self.elapsed_s)}"
        if self.finished:
            when = f"done in {when}"
        elif left is not None:
            when += f", about {format_duration(left)} left"
        note = f" ({self.note})" if self.note else ""
        return f"{self.stage} {count} {when}{note}"


def time_left(seconds: float, counted: int, remaining: int) -> float | None:
    """Seconds left when ``counted`` units took ``seconds`` and ``remaining`` are to come; None
    before a unit has been timed."""
    if counted <= 0 or seconds <= 0:
        return None
    return seconds * max(remaining, 0) / counted


def format_duration(seconds: float) -> str:
    """``"45 s"``, ``"3 min 05 s"``, ``"1 h 02 min"``."""
    if not math.isfinite(seconds):
        return "?"
    s = round(max(seconds, 0.0))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


def _bar(done: int, total: int | None, width: int = 20) -> str:
    if not total:
        return ""
    k = min(width, round(width * done / total))
    return "[" + "#" * k + "." * (width - k) + "]"


def parse_line(line: str) -> Progress | None:
    """The :class:`Progress` of a ``"json"`` line; None for any other line."""
    if not line.startswith(PREFIX):
        return None
    try:
        d = json.loads(line[len(PREFIX) :])
        left = d.get("left_s")
        return Progress(
            str(d["stage"]),
            int(d["done"]),
            None if d.get("total") is None else int(d["total"]),
            float(d["elapsed_s"]),
            str(d.get("note", "")),
            None if left is None else float(left),
        )
    except (ValueError, KeyError, TypeError):
        return None


class ProgressReporter:
    """Shows :class:`Progress` as text or JSON lines (module docstring).

    Parameters
    ----------
    mode : {"text", "json", "none"}
    stream : text stream, optional
        Default ``sys.stderr``.
    prefix : str
        Put before each text line (``"calibration: "``).
    interval_s : float
        Least time between two text lines when the stream is not a terminal.
    """

    def __init__(
        self,
        mode: str = "text",
        stream: TextIO | None = None,
        prefix: str = "",
        interval_s: float = 15.0,
    ) -> None:
        if mode not in ("text", "json", "none"):
            raise ValueError(f"progress mode: expected text, json or none, got {mode!r}")
        self.mode = mode
        self.stream = stream or sys.stderr
        self.prefix = prefix
        self.interval_s = interval_s
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._starts: dict[str, tuple[float, int]] = {}
        self._shown: dict[str, float] = {}
        self._open_line = False

    def begin(self, stage: str, total: int | None = None, note: str = "") -> None:
        """Start the clock of ``stage`` (and show it at 0)."""
        self._starts[stage] = (time.perf_counter(), 0)
        self._shown.pop(stage, None)
        self.show(Progress(stage, 0, total, 0.0, note))

    def update(self, stage: str, done: int, total: int | None = None, note: str = "") -> None:
        """``done`` units of ``stage`` finished. Without :meth:`begin`, the clock starts at the
        first call, and the pace is taken over the units finished since."""
        now = time.perf_counter()
        t0, done0 = self._starts.setdefault(stage, (now, done))
        left = None
        if total is not None and done < total:
            left = time_left(now - t0, done - done0, total - done)
        self.show(Progress(stage, done, total, now - t0, note, left))

    def event(self, e: Event) -> None:
        """Show an event of :mod:`analysis.events`: a counted unit as the stage's count, an
        optimiser's iterations as a count of their own, a milestone as a line of its own."""
        if isinstance(e, UnitDone):
            note = e.label or ("" if e.cost is None else f"metric {e.cost:.4g}")
            self.update(e.stage, e.done, e.total, note)
        elif isinstance(e, Iteration):
            total = e.iteration if e.last else None
            self.update(f"{e.stage} iterations", e.iteration, total, f"metric {e.cost:.6g}")
        elif isinstance(e, StageDone):
            self.milestone(e)

    def milestone(self, e: StageDone) -> None:
        """Show a milestone at once (never held back by the interval)."""
        if self.mode == "none":
            return
        if self.mode == "json":
            n = e.count if e.count is not None else 0
            p = Progress(e.stage, n, n, e.seconds or 0.0, e.detail())
            self._write(PREFIX + json.dumps(asdict(p)))
        else:
            self._write(self.prefix + e.text())

    def show(self, p: Progress) -> None:
        """Show ``p`` if it is due (always at its start and end)."""
        if self.mode == "none":
            return
        now = time.perf_counter()
        last = self._shown.get(p.stage)
        interval = _JSON_INTERVAL_S if self.mode == "json" else self.interval_s
        if self.tty and self.mode == "text":
            interval = 0.2
        if last is not None and not p.finished and now - last < interval:
            return
        self._shown[p.stage] = now
        if self.mode == "json":
            self._write(PREFIX + json.dumps(asdict(p)))
        elif self.tty and not p.finished:
            self.stream.write("\r" + (self.prefix + p.text())[:119].ljust(119))
            self.stream.flush()
            self._open_line = True
        else:
            self._write(self.prefix + p.text())

    def _write(self, text: str) -> None:
        if self._open_line:
            self.stream.write("\r" + " " * 119 + "\r")
            self._open_line = False
        self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End a line left open on a terminal."""
        if self._open_line:
            self.stream.write("\n")
            self.stream.flush()
            self._open_line = False
