"""The real GUI as a person starts it: ``python -m rig gui`` in its own process on a virtual X
server (Xvfb), with Qt's X11 platform plugin, not the offscreen one of the other GUI tests.

The test waits for the window (``xdotool search --sync``), takes a screenshot of it from the X
server (ImageMagick's ``import``), checks that it shows something, and quits with Ctrl+Q as
an operator would: the process must end with exit code 0. ``make gui-deps`` installs Xvfb,
xdotool, x11-utils, imagemagick and the X11 plugin's libraries; without Xvfb the test is
skipped, and a missing tool besides it fails the test with the command that installs it.
``CLEARANCE_RIG_SCREENSHOTS=docs/screenshots`` keeps the screenshot as ``gui-main.png``.
"""

from __future__ import annotations

import os
import select
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.rig.gui.gui_helpers import SCREENSHOTS

ROOT = Path(__file__).resolve().parents[3]
TITLE = "clearance-rig lab"
SCREEN = (1600, 1000)

pytestmark = [
    pytest.mark.slow,
    pytest.mark.xvfb,
    pytest.mark.skipif(
        shutil.which("Xvfb") is None,
        reason="Xvfb is not installed: the real GUI needs a virtual X server "
        "('make gui-deps', or apt-get install xvfb xdotool x11-utils imagemagick)",
    ),
]


def _tool(name: str, package: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} is missing beside Xvfb: apt-get install -y {package} (make gui-deps)")
    return path


@pytest.fixture
def x_display():
    """A private virtual X server (its number chosen by Xvfb): its DISPLAY string."""
    read, write = os.pipe()
    server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write), "-screen", "0", f"{SCREEN[0]}x{SCREEN[1]}x24"]
        + ["-nolisten", "tcp", "-noreset"],
        pass_fds=(write,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    os.close(write)
    number = b""
    deadline = time.monotonic() + 30
    while not number.endswith(b"\n") and time.monotonic() < deadline:
        ready, _, _ = select.select([read], [], [], 0.5)
        if ready:
            chunk = os.read(read, 16)
            if not chunk:
                break
            number += chunk
    os.close(read)
    if not number.strip():
        server.kill()
        pytest.fail(f"Xvfb did not start: {server.communicate()[1].decode(errors='replace')}")
    try:
        yield f":{number.decode().strip()}"
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()


def _screen_rgb(display: str, window: str) -> np.ndarray:
    """The window's pixels as the X server has them, shape (height, width, 3)."""
    env = {**os.environ, "DISPLAY": display}
    size = subprocess.run(
        ["xdotool", "getwindowgeometry", "--shell", window],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    geometry = dict(line.split("=", 1) for line in size.split())
    width, height = int(geometry["WIDTH"]), int(geometry["HEIGHT"])
    raw = subprocess.run(
        ["import", "-window", window, "-depth", "8", "rgb:-"],
        env=env,
        capture_output=True,
        check=True,
        timeout=60,
    ).stdout
    assert len(raw) == width * height * 3, (len(raw), width, height)
    return np.frombuffer(raw, dtype=np.uint8).reshape(height, width, 3)


def test_the_real_gui_opens_its_window_on_x11_and_quits_cleanly(x_display, tmp_path):
    _tool("xdotool", "xdotool")
    _tool("import", "imagemagick")
    env = {k: v for k, v in os.environ.items() if k not in ("QT_QPA_PLATFORM", "WAYLAND_DISPLAY")}
    env.pop("CLEARANCE_RIG_RUNS", None)
    home = tmp_path / "home"
    home.mkdir()
    env.update(DISPLAY=x_display, HOME=str(home), XDG_RUNTIME_DIR=str(tmp_path))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    gui = subprocess.Popen(
        [sys.executable, "-m", "rig", "gui"],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        found = subprocess.run(
            ["xdotool", "search", "--sync", "--onlyvisible", "--name", f"^{TITLE}$"],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        if found.returncode != 0 or gui.poll() is not None:
            gui.kill()
            out, err = gui.communicate()
            pytest.fail(f"no window '{TITLE}' (GUI exit {gui.returncode}): {err[-3000:]}")
        window = found.stdout.split()[0]

        # what a person sees: the window painted, with text and plots (not one flat colour)
        deadline = time.monotonic() + 30
        while True:
            pixels = _screen_rgb(x_display, window)
            grey = pixels.astype(float).mean(axis=2)
            colours = len(np.unique(pixels.reshape(-1, 3)[::7], axis=0))
            if (grey.std() > 20 and colours > 50) or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert pixels.shape[:2] == (SCREEN[1], SCREEN[0])
        assert grey.std() > 20 and colours > 50, (grey.std(), colours)
        assert (grey > 200).mean() > 0.3 and (grey < 100).mean() > 0.005  # a page with text
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        shot = SCREENSHOTS / "gui-main.png"
        subprocess.run(["import", "-window", window, str(shot)], env=env, check=True, timeout=60)
        assert shot.stat().st_size > 20_000

        # the operator quits with Ctrl+Q: the GUI closes its window and ends with exit code 0
        subprocess.run(["xdotool", "windowfocus", "--sync", window], env=env, timeout=30)
        subprocess.run(
            ["xdotool", "key", "--clearmodifiers", "ctrl+q"], env=env, check=True, timeout=30
        )
        out, err = gui.communicate(timeout=60)
        assert gui.returncode == 0, err[-3000:]
        assert "error" not in err.lower(), err[-3000:]
        # nothing was written where it was started, nor made in the home folder
        assert sorted(p.name for p in tmp_path.iterdir()) == ["home"]
    finally:
        if gui.poll() is None:
            gui.kill()
            gui.communicate()
