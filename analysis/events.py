"""Events of long work and the bus that delivers them: one protocol for the rig and the analysis.

Whatever takes long reports what it does as :class:`Event` objects handed to a listener, a
callable taking one event: a stepped-sine run (:mod:`rig.run.events`), a calibration, a
cross-validation, a diagnosis or a recalibration (the classes below). A front end can pass a
function, or :meth:`EventBus.publish` to fan events out to several subscribers; it tells events
apart by their class, never by parsing text.

The analysis's events:

- :class:`UnitDone`: one unit of a counted stage finished (a Latin hypercube start scored, a
  candidate screened, a cross-validation fold), with how many there are;
- :class:`Iteration`: an optimiser's iteration (Levenberg-Marquardt's accepted step and its
  cost), and with ``last`` set, where it stopped;
- :class:`StageDone`: a milestone of a longer job (the comparison made, the screen finished, the
  verifications so far) with the figures it reached.

Listeners run in the worker's thread while the work waits: keep them short (a GUI hands the
event to its own thread). On a bus, an exception in a subscriber is logged and does not stop the
work.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "Event",
    "EventBus",
    "Iteration",
    "Listener",
    "StageDone",
    "Subscription",
    "UnitDone",
    "iteration",
    "iterations",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Event:
    """Base of every event; ``time_s`` is the POSIX time it was created."""

    time_s: float = field(default_factory=time.time, kw_only=True)


#: What receives events: any callable taking one :class:`Event`.
Listener = Callable[[Event], Any]


@dataclass(frozen=True)
class UnitDone(Event):
    """One unit of a counted stage finished.

    Attributes
    ----------
    stage : str
        What is counted, e.g. ``"Latin hypercube starts"``, ``"screen"``.
    done : int
        Units finished (1 after the first).
    total : int or None
        Units in all, None when not known beforehand.
    label : str
        What the last unit was (a candidate's label), or ``""``.
    cost : float or None
        The last unit's figure (a start's metric), None when it has none.
    """

    stage: str
    done: int
    total: int | None
    label: str = ""
    cost: float | None = None


@dataclass(frozen=True)
class Iteration(Event):
    """An optimiser's iteration.

    Attributes
    ----------
    stage : str
        Which optimisation (``"Levenberg-Marquardt"``, ``"joint refinement"``).
    iteration : int
        0 at the start point, then one per accepted step.
    cost : float
        Half the sum of squared weighted residuals there.
    x : tuple of float
        The (scaled) parameters there; empty when not reported.
    last : bool
        The optimisation stopped here.
    """

    stage: str
    iteration: int
    cost: float
    x: tuple[float, ...] = ()
    last: bool = False


@dataclass(frozen=True)
class StageDone(Event):
    """A milestone of a longer job and the figures it reached (None: not part of it).

    Attributes
    ----------
    stage : str
        The milestone, e.g. ``"compared"``, ``"screened"``, ``"verified"``.
    count : int or None
        How many things it covered (candidates, fits, starts).
    rms_over_noise : float or None
        The residual reached, as a multiple of the noise.
    cost : float or None
        An optimiser's metric reached.
    seconds : float or None
        Wall time the stage took.
    values : mapping of str to float
        Parameter values it found (a screen's estimate, a linear recalibration's).
    note : str
        Anything else for a person (the best candidate's label).
    """

    stage: str
    count: int | None = None
    rms_over_noise: float | None = None
    cost: float | None = None
    seconds: float | None = None
    values: Mapping[str, float] = field(default_factory=dict)
    note: str = ""

    def text(self) -> str:
        """One line for a person: the stage and the figures it has."""
        parts = [] if self.count is None else [f"{self.count}"]
        detail = self.detail()
        return f"{self.stage}: {', '.join([*parts, detail] if detail else parts)}"

    def detail(self) -> str:
        """The figures other than ``count`` (``"residual 1.02 x noise, 12.3 s"``)."""
        parts = []
        if self.rms_over_noise is not None:
            parts.append(f"residual {self.rms_over_noise:.4g} x noise")
        if self.cost is not None:
            parts.append(f"metric {self.cost:.4g}")
        if self.values:
            parts.append(", ".join(f"{k}={v:.4g}" for k, v in self.values.items()))
        if self.note:
            parts.append(self.note)
        if self.seconds is not None:
            parts.append(f"{self.seconds:.1f} s")
        return ", ".join(parts)


def iteration(stage: str, entry: Mapping[str, Any], last: bool = False) -> Iteration:
    """The :class:`Iteration` of a Levenberg-Marquardt history entry (``iteration``, ``cost``
    and ``x``, as :func:`analysis.calibration.lm.least_squares_lm` records them)."""
    return Iteration(
        stage,
        int(entry["iteration"]),
        float(entry["cost"]),
        tuple(float(v) for v in entry.get("x", ())),
        last,
    )


def iterations(stage: str, progress: Listener | None) -> Callable[[Mapping], None] | None:
    """An optimiser's per-iteration callback that hands ``progress`` an :class:`Iteration`
    (None without a listener, so the optimiser skips the call)."""
    if progress is None:
        return None
    return lambda entry: progress(iteration(stage, entry))


@dataclass(frozen=True)
class Subscription:
    """Handle returned by :meth:`EventBus.subscribe`; :meth:`cancel` unsubscribes."""

    bus: EventBus
    key: int

    def cancel(self) -> None:
        self.bus.unsubscribe(self)


class EventBus:
    """Delivers events to subscribed callbacks (thread-safe).

    Examples
    --------
    >>> bus = EventBus()
    >>> sub = bus.subscribe(print, kinds=(Iteration,))
    >>> sub.cancel()
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subs: dict[int, tuple[Listener, tuple[type, ...] | None]] = {}
        self._keys = itertools.count()

    def subscribe(self, callback: Listener, kinds: tuple[type, ...] | None = None) -> Subscription:
        """Call ``callback(event)`` for every event (or only those of the given classes)."""
        if not callable(callback):
            raise TypeError(f"subscribe: callback must be callable, got {callback!r}")
        with self._lock:
            key = next(self._keys)
            self._subs[key] = (callback, tuple(kinds) if kinds else None)
        return Subscription(self, key)

    def unsubscribe(self, subscription: Subscription) -> None:
        """Stop delivering to a subscription (no error if already gone)."""
        with self._lock:
            self._subs.pop(subscription.key, None)

    def publish(self, event: Event) -> None:
        """Deliver ``event`` to the subscribers at the time of the call."""
        with self._lock:
            subs = list(self._subs.values())
        for callback, kinds in subs:
            if kinds is not None and not isinstance(event, kinds):
                continue
            try:
                callback(event)
            except Exception:
                logger.exception("event subscriber %r failed on %s", callback, type(event).__name__)
