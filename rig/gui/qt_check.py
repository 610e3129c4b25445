"""A check of the Qt binding before the GUI starts.

PySide6 6.12.0 on Python 3.11 returns ``None`` from every Qt method that returns nothing
without taking a reference to it, so each such call drops one of ``None`` 's references;
after a few thousand calls (a second of plotting) the interpreter deallocates ``None`` and
aborts. From Python 3.12 on ``None``, ``True`` and ``False`` are immortal and the defect is
harmless. :func:`binding_problem` measures it directly, so the GUI refuses to start with a
sentence instead of crashing in the middle of a run.
"""

from __future__ import annotations

import sys

__all__ = ["binding_problem"]

_CALLS = 64


def binding_problem() -> str:
    """What is wrong with the Qt binding ("" when nothing is)."""
    if sys.version_info >= (3, 12):
        return ""  # None is immortal: a lost reference does no harm
    import PySide6
    from PySide6 import QtCore

    point = QtCore.QPoint()
    before = sys.getrefcount(None)
    for i in range(_CALLS):
        point.setX(i)
    lost = before - sys.getrefcount(None)
    if lost < _CALLS // 2:
        return ""
    return (
        f"PySide6 {PySide6.__version__} loses a reference to None on every Qt call that "
        f"returns nothing ({lost} of {_CALLS} calls here); on Python "
        f"{sys.version_info.major}.{sys.version_info.minor} the process aborts after a few "
        "thousand such calls. Install a PySide6 without this defect: "
        "pip install 'PySide6-Essentials>=6.6,!=6.12.0'"
    )
