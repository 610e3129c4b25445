"""A lab user's first hour: the GUI says why it cannot open a window instead of aborting."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from rig.gui.qt_check import XCB_LIBRARIES, display_problem, missing_xcb_libraries

ROOT = Path(__file__).resolve().parents[3]

# -- no display, missing system libraries --------------------------------------------------------


def _all_load(_name: str) -> bool:
    return True


def test_no_display_is_said_in_a_sentence():
    problem = display_problem({}, platform="linux", loads=_all_load)
    assert problem.startswith("no display: DISPLAY and WAYLAND_DISPLAY are unset")
    assert "xvfb-run" in problem


def test_headless_platforms_and_other_systems_need_no_display():
    for platform in ("offscreen", "minimal", "vnc"):
        assert display_problem({"QT_QPA_PLATFORM": platform}, platform="linux") == ""
    assert display_problem({}, platform="win32") == ""
    assert display_problem({}, platform="darwin") == ""
    wayland = {"WAYLAND_DISPLAY": "wayland-0", "XDG_SESSION_TYPE": "wayland"}
    assert display_problem(wayland, platform="linux", loads=lambda n: False) == ""


def test_missing_xcb_libraries_are_named_with_the_command_that_installs_them():
    absent = {"libxcb-cursor.so.0", "libxcb-icccm.so.4", "libxcb-keysyms.so.1"}
    problem = display_problem(
        {"DISPLAY": ":0"},
        platform="linux",
        loads=lambda name: name not in absent,
        x_server_answers=lambda d: pytest.fail("the libraries come first"),
    )
    assert "libxcb-cursor.so.0, libxcb-icccm.so.4, libxcb-keysyms.so.1" in problem
    assert problem.endswith("apt-get install -y libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1")


def test_an_x_server_that_does_not_answer_is_said():
    problem = display_problem(
        {"DISPLAY": ":77"}, platform="linux", loads=_all_load, x_server_answers=lambda d: False
    )
    assert problem.startswith("no display: the X server DISPLAY=:77 does not accept")
    fine = display_problem(
        {"DISPLAY": ":77"}, platform="linux", loads=_all_load, x_server_answers=lambda d: True
    )
    assert fine == ""


def test_the_library_check_loads_real_libraries():
    assert missing_xcb_libraries(lambda name: name in XCB_LIBRARIES) == []
    if sys.platform.startswith("linux"):
        missing = missing_xcb_libraries()
        assert set(missing) <= set(XCB_LIBRARIES)


def test_rig_gui_without_a_display_exits_with_a_message_not_a_core_dump(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.pop("QT_QPA_PLATFORM", None)
    done = subprocess.run(
        [sys.executable, "-m", "rig", "gui"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr  # a usage error, not 134 (SIGABRT)
    assert "error: no display: DISPLAY and WAYLAND_DISPLAY are unset" in done.stderr
    assert "Could not load the Qt platform plugin" not in done.stderr
    assert not list(tmp_path.iterdir())
