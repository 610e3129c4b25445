"""Slow work off the GUI thread: compare, diagnose, augment, plan.

A :class:`Task` runs one function in a ``QThread``; the function gets a ``report(event)``
listener (the analysis functions' ``progress`` argument, :mod:`analysis.events`) whose events
arrive on the GUI thread as the :attr:`Task.progress` signal, followed by :attr:`Task.done` with
the result or :attr:`Task.failed` with the error in words.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore

from analysis.events import Event, Listener

__all__ = ["Task"]

logger = logging.getLogger(__name__)


class Task(QtCore.QThread):
    """One piece of work in a worker thread.

    Parameters
    ----------
    name : str
        What it does, for messages ("diagnosis").
    work : callable(report) -> object
        Runs in the worker thread; calls ``report(event)`` to show progress.
    """

    progress = QtCore.Signal(object)
    done = QtCore.Signal(object)
    failed = QtCore.Signal(str)

    def __init__(
        self, name: str, work: Callable[[Listener], Any], parent: QtCore.QObject | None = None
    ) -> None:
        super().__init__(parent)
        self.name = name
        self.work = work
        self.result: Any = None
        self.error = ""

    def _report(self, event: Event) -> None:
        self.progress.emit(event)

    def run(self) -> None:  # noqa: D401 - QThread entry point
        try:
            self.result = self.work(self._report)
        except Exception as exc:  # shown to the user; the GUI stays up
            logger.exception("%s failed", self.name)
            self.error = f"{self.name} failed: {type(exc).__name__}: {exc}"
            self.failed.emit(self.error)
            return
        self.done.emit(self.result)
