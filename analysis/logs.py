"""Logging tools of the analysis command line: one line for a flood of expected warnings.

A calibration evaluates thousands of trial parameter sets, many far from the data, and the
harmonic balance warns for every step that does not converge at one of them (``MHB step N
(f Hz) did not converge: ...``): 3 000 identical lines that hide everything else, about
failures that are expected. :func:`summarise_repeats` wraps one stage of a command: while it
runs, records matching a :class:`Repeated` kind are counted and passed on at DEBUG level (shown
with ``--debug``, dropped otherwise); at its end one WARNING line gives their number.

The library itself (``analysis.mhb``) keeps warning per step: a script that calls it directly
still sees every failure.

Worker processes forked while a stage runs (the local process pools of the calibration, the
planning and the diagnosis) inherit the stage and count into memory shared with the command's
process, so the summary includes their steps. Workers started otherwise (a Dask cluster)
log under their own configuration.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "INPUT_FILE_OPTIONS",
    "MHB_NOT_CONVERGED",
    "Repeated",
    "StageCounts",
    "add_debug_option",
    "configure_logging",
    "note_inputs",
    "parse_assignments",
    "summarise_repeats",
]

log = logging.getLogger("analysis")


@dataclass(frozen=True)
class Repeated:
    """A kind of record expected many times in one stage.

    Attributes
    ----------
    logger : str
        The logger that emits it (the filter sits on that logger).
    pattern : str
        Regular expression searched in the formatted message.
    summary : str
        The stage's one WARNING line, ``{n}`` the count.
    summary_one : str
        The line for a count of one (default: ``summary``).
    """

    logger: str
    pattern: str
    summary: str
    summary_one: str = ""

    def line(self, n: int) -> str:
        """The summary line for ``n`` records."""
        return (
            (self.summary_one or self.summary).format(n=n) if n == 1 else self.summary.format(n=n)
        )


#: Harmonic-balance steps that did not converge (``analysis.mhb.sweep``): expected by the
#: hundred when a calibration, a plan or a diagnosis tries parameters far from the data.
MHB_NOT_CONVERGED = Repeated(
    "analysis.mhb.sweep",
    r"^MHB step \d+ .*did not converge",
    "{n} MHB steps did not converge (expected for trial parameters far from the data); "
    "run with --debug for each",
    "1 MHB step did not converge (expected for trial parameters far from the data); "
    "run with --debug to see it",
)

_ORIGINAL_LEVEL = "repeat_original_levelno"


class StageCounts:
    """Counts of one stage by kind, kept in memory shared with forked worker processes."""

    def __init__(self, stage: str, kinds: Sequence[Repeated]) -> None:
        self.stage = stage
        self.kinds = tuple(kinds)
        self._patterns = [re.compile(k.pattern) for k in self.kinds]
        try:
            self._n: Any = multiprocessing.Array("q", len(self.kinds))
        except OSError:  # pragma: no cover - no shared memory here: count in this process
            self._n = [0] * len(self.kinds)

    def match(self, record: logging.LogRecord) -> int | None:
        """The index of the kind ``record`` is, or None."""
        for i, (kind, pattern) in enumerate(zip(self.kinds, self._patterns, strict=True)):
            if record.name == kind.logger and pattern.search(record.getMessage()):
                return i
        return None

    def add(self, i: int) -> None:
        lock = getattr(self._n, "get_lock", None)
        with lock() if lock else contextlib.nullcontext():
            self._n[i] += 1

    @property
    def counts(self) -> dict[Repeated, int]:
        """Records counted so far, by kind."""
        return dict(zip(self.kinds, list(self._n), strict=True))


#: The stages running in this process, innermost last: a record counts in the innermost only.
_stages: list[StageCounts] = []


class _RepeatFilter(logging.Filter):
    """On an emitting logger: counts matching WARNING records in the innermost stage and
    passes them on at DEBUG level (dropped unless the logger is enabled for DEBUG)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not _stages:
            return True
        level = getattr(record, _ORIGINAL_LEVEL, record.levelno)
        if level < logging.WARNING:
            return True
        stage = _stages[-1]
        i = stage.match(record)
        if i is None:
            return True
        if not hasattr(record, _ORIGINAL_LEVEL):
            stage.add(i)
            setattr(record, _ORIGINAL_LEVEL, record.levelno)
            record.levelno, record.levelname = logging.DEBUG, logging.getLevelName(logging.DEBUG)
        return logging.getLogger(record.name).isEnabledFor(logging.DEBUG)


_filter = _RepeatFilter()


@contextlib.contextmanager
def summarise_repeats(
    stage: str,
    kinds: Sequence[Repeated] = (MHB_NOT_CONVERGED,),
    logger: logging.Logger | None = None,
) -> Iterator[StageCounts]:
    """Count the ``kinds`` of record during one stage; log one WARNING line per kind at its end.

    Parameters
    ----------
    stage : str
        The stage's name, the start of each summary line (e.g. ``"calibrate"``).
    kinds : sequence of Repeated
        The records to count (default: MHB steps that did not converge).
    logger : logging.Logger, optional
        Where the summary goes (default: ``analysis``).

    Yields
    ------
    StageCounts
        Its ``counts`` so far. Stages nest: a record counts in the innermost one only.

    Examples
    --------
    >>> with summarise_repeats("calibrate"):  # doctest: +SKIP
    ...     calibrate_nonlinear(model, data, settings)
    WARNING analysis: calibrate: 3412 MHB steps did not converge (expected ...)
    """
    counts = StageCounts(stage, kinds)
    loggers = [logging.getLogger(name) for name in dict.fromkeys(k.logger for k in kinds)]
    for lg in loggers:
        if _filter not in lg.filters:
            lg.addFilter(_filter)
    _stages.append(counts)
    try:
        yield counts
    finally:
        _stages.remove(counts)
        if not _stages:
            for lg in loggers:
                lg.removeFilter(_filter)
        for kind, n in counts.counts.items():
            if n:
                (logger or log).warning("%s: %s", stage, kind.line(n))


def add_debug_option(parser) -> None:
    """``-v/--verbose`` (progress) and ``--debug`` (also every repeated record) on ``parser``."""
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    parser.add_argument(
        "--debug",
        action="store_true",
        help="log details too, e.g. every MHB step that did not converge",
    )


def configure_logging(args) -> None:
    """Logging of a command line: WARNING, INFO with ``-v``, the analysis' DEBUG with ``--debug``
    (other libraries stay at INFO: their debug output is not the user's concern)."""
    debug = getattr(args, "debug", False)
    logging.basicConfig(
        level=logging.INFO if (getattr(args, "verbose", False) or debug) else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if debug:
        logging.getLogger("analysis").setLevel(logging.DEBUG)


#: The options of the analysis commands that name a measurement file the command reads.
INPUT_FILE_OPTIONS = ("run", "linear_run")


def note_inputs(args, logger: logging.Logger | None = None) -> list[str]:
    """Log a WARNING note for each input measurement file whose run did not end normally.

    An incomplete file (status ``running`` or ``aborted``/``failed``) is analysed as it is, its
    recorded steps only; the note says so, with the steps recorded against those planned and
    the reason the run ended (:func:`analysis.measurement_file.incomplete_note`).
    """
    from analysis.measurement_file import input_notes

    paths = [getattr(args, name, None) for name in INPUT_FILE_OPTIONS]
    notes = input_notes([p for p in paths if isinstance(p, str)])
    for note in notes:
        (logger or log).warning("note: %s", note)
    return notes


def parse_assignments(items, option: str = "--set") -> dict[str, float]:
    """``NAME=NUMBER`` command-line items as a mapping; a malformed one ends the command with
    a message naming it (``--set 'gap=x': expected NAME=NUMBER``)."""
    values = {}
    for item in items or []:
        name, _, val = item.partition("=")
        try:
            values[name.strip()] = float(val)
        except ValueError:
            raise SystemExit(f"{option} {item!r}: expected NAME=NUMBER") from None
    return values
