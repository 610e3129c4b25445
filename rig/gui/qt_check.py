"""Checks before the GUI starts: the Qt binding, the display and the system libraries.

Qt aborts the interpreter (a core dump, exit code 134) when its platform plugin cannot load:
without a display, or when the X11 plugin's system libraries (``libxcb-cursor0`` and others
that a minimal system lacks) are missing. :func:`display_problem` finds both in Python before a
``QApplication`` exists, and names the missing libraries and the command that installs them.

PySide6 6.12.0 on Python 3.11 returns ``None`` from every Qt method that returns nothing
without taking a reference to it, so each such call drops one of ``None`` 's references;
after a few thousand calls (a second of plotting) the interpreter deallocates ``None`` and
aborts. From Python 3.12 on ``None``, ``True`` and ``False`` are immortal and the defect is
harmless. :func:`binding_problem` measures it directly, so the GUI refuses to start with a
sentence instead of crashing in the middle of a run.
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Callable, Mapping

__all__ = ["XCB_LIBRARIES", "binding_problem", "display_problem", "missing_xcb_libraries"]

#: The system libraries Qt's X11 platform plugin (``libqxcb.so``, Qt 6.5 and later) loads, and
#: the Debian/Ubuntu package of each. ``QT_DEBUG_PLUGINS=1`` shows the first one missing.
XCB_LIBRARIES: dict[str, str] = {
    "libxcb.so.1": "libxcb1",
    "libX11.so.6": "libx11-6",
    "libX11-xcb.so.1": "libx11-xcb1",
    "libxcb-cursor.so.0": "libxcb-cursor0",
    "libxcb-icccm.so.4": "libxcb-icccm4",
    "libxcb-image.so.0": "libxcb-image0",
    "libxcb-keysyms.so.1": "libxcb-keysyms1",
    "libxcb-randr.so.0": "libxcb-randr0",
    "libxcb-render.so.0": "libxcb-render0",
    "libxcb-render-util.so.0": "libxcb-render-util0",
    "libxcb-shape.so.0": "libxcb-shape0",
    "libxcb-shm.so.0": "libxcb-shm0",
    "libxcb-sync.so.1": "libxcb-sync1",
    "libxcb-util.so.1": "libxcb-util1",
    "libxcb-xfixes.so.0": "libxcb-xfixes0",
    "libxcb-xkb.so.1": "libxcb-xkb1",
    "libxkbcommon.so.0": "libxkbcommon0",
    "libxkbcommon-x11.so.0": "libxkbcommon-x11-0",
}

#: Platforms that need no display server (tests, remote viewers, a framebuffer).
_HEADLESS = ("offscreen", "minimal", "minimalegl", "vnc", "linuxfb", "eglfs", "vkkhrdisplay")


def _loads(name: str) -> bool:
    try:
        ctypes.CDLL(name)
    except OSError:
        return False
    return True


def missing_xcb_libraries(loads: Callable[[str], bool] = _loads) -> list[str]:
    """The libraries of :data:`XCB_LIBRARIES` the dynamic loader cannot load."""
    return [name for name in XCB_LIBRARIES if not loads(name)]


def _x_server_answers(display: str) -> bool:
    """Whether the X server ``display`` accepts a connection (libxcb, as Qt connects)."""
    try:
        xcb = ctypes.CDLL("libxcb.so.1")
    except OSError:
        return True  # reported as a missing library instead
    xcb.xcb_connect.restype = ctypes.c_void_p
    xcb.xcb_connect.argtypes = [ctypes.c_char_p, ctypes.c_void_p]
    xcb.xcb_connection_has_error.argtypes = [ctypes.c_void_p]
    xcb.xcb_disconnect.argtypes = [ctypes.c_void_p]
    connection = xcb.xcb_connect(display.encode(), None)
    try:
        return connection is not None and xcb.xcb_connection_has_error(connection) == 0
    finally:
        if connection is not None:
            xcb.xcb_disconnect(connection)


def display_problem(
    environ: Mapping[str, str] | None = None,
    *,
    platform: str | None = None,
    loads: Callable[[str], bool] = _loads,
    x_server_answers: Callable[[str], bool] = _x_server_answers,
) -> str:
    """Why Qt could not open a window here ("" when nothing stops it).

    Parameters
    ----------
    environ : mapping, optional
        The environment (default ``os.environ``): ``QT_QPA_PLATFORM``, ``DISPLAY``,
        ``WAYLAND_DISPLAY``, ``XDG_SESSION_TYPE``.
    platform : str, optional
        ``sys.platform`` (default this one's); only Linux and the BSDs use X11 or Wayland.
    loads, x_server_answers : callable
        Whether a shared library loads, whether an X server answers (replaced in tests).
    """
    env = os.environ if environ is None else environ
    if not (platform or sys.platform).startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return ""
    chosen = env.get("QT_QPA_PLATFORM", "").split(";")[0].split(":")[0].strip().lower()
    if chosen in _HEADLESS:
        return ""
    display, wayland = env.get("DISPLAY", ""), env.get("WAYLAND_DISPLAY", "")
    if chosen.startswith("wayland"):
        if wayland:
            return ""
        return (
            f"no display: QT_QPA_PLATFORM={env['QT_QPA_PLATFORM']} asks for Wayland but "
            "WAYLAND_DISPLAY is unset. Start the GUI from the desktop session, or unset "
            "QT_QPA_PLATFORM to use X11."
        )
    if not chosen and wayland and env.get("XDG_SESSION_TYPE", "") == "wayland":
        return ""  # Qt opens a Wayland window first
    if not display:
        return (
            "no display: DISPLAY and WAYLAND_DISPLAY are unset, so the GUI has nowhere to open "
            "its window. Start it from a desktop session, over 'ssh -X', or on a virtual X "
            "server ('xvfb-run -a python -m rig gui'); the command line ('python -m rig run', "
            "'python -m rig workflow') needs no display."
        )
    missing = missing_xcb_libraries(loads)
    if missing:
        packages = sorted({XCB_LIBRARIES[name] for name in missing})
        return (
            "Qt's X11 platform plugin (xcb) cannot load: these system libraries are missing: "
            f"{', '.join(missing)}. Install them (as root): apt-get install -y "
            f"{' '.join(packages)}"
        )
    if not x_server_answers(display):
        return (
            f"no display: the X server DISPLAY={display} does not accept a connection (is it "
            "running, and may this user connect to it? 'xdpyinfo' tells). Start the GUI from "
            "the desktop session or on a virtual X server ('xvfb-run -a python -m rig gui')."
        )
    return ""


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
