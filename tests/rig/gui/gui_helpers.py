"""Helpers of the GUI tests: screenshots, the window on a test lock.

Screenshots go to a temporary folder; ``CLEARANCE_RIG_SCREENSHOTS=docs/screenshots pytest
tests/rig/gui`` refreshes the ones docs/gui.md shows.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

SCREENSHOTS = Path(
    os.environ.get("CLEARANCE_RIG_SCREENSHOTS")
    or Path(tempfile.gettempdir()) / "clearance-rig-screenshots"
)


def screenshot(widget, name: str, size: tuple[int, int] | None = None) -> Path:
    """Save ``widget`` as ``<SCREENSHOTS>/<name>`` and check the file."""
    if size is not None:
        widget.resize(*size)
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    path = SCREENSHOTS / name
    pixmap = widget.grab()
    assert pixmap.width() > 300 and pixmap.height() > 200
    assert pixmap.save(str(path)), f"could not write {path}"
    assert path.stat().st_size > 10_000
    return path


def make_window(qtbot, lock_dir, **controller_options):
    """The main window, running tests in this process on a private lock directory."""
    from rig.gui.app import LabWindow
    from rig.gui.controller import LocalRunController

    controller = LocalRunController(lock_dir=str(lock_dir), **controller_options)
    window = LabWindow(controller)
    # a test that fails mid-run must not leave the engine running: abort and wait first
    qtbot.addWidget(window, before_close_func=lambda w: w.acquisition.shutdown())
    window.resize(1600, 1000)
    window.show()
    return window


def prepare_run(window, path: Path, sample_rate_hz: float = 10240.0, truth: str = "reference"):
    """Point the acquisition tab at ``path`` on the simulated rig at a reduced sample rate."""
    panel = window.acquisition.setup_panel
    panel.setup_editor.form.widget("daq.sample_rate_hz").setText(f"{sample_rate_hz:g}")
    panel.run_box.truth.setCurrentText(truth)
    panel.run_box.seed.setText("5")
    panel.run_box.path.setText(str(path))
    assert panel.check(), panel.problem
    return panel
