"""Browse a measurement file: how the run ended, its steps, its FRFs.

Reads with :func:`analysis.measurement_file.read_measurement` (the one reader of the format),
so a finished run, an interrupted one (its completed steps) and a random test all open. An
unfinished stepped-sine run can be handed to the acquisition panel to be completed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from analysis.measurement_file import (
    MeasurementFileError,
    RandomData,
    SteppedSineData,
    read_measurement,
)
from rig.gui.frf_view import FrfPlots, frf_unit, sweep_series
from rig.gui.style import ALARM, OK, WARN, color, make_plot, no_edit, status_chip

__all__ = ["RunBrowser"]

_STEP_COLUMNS = (
    "step",
    "level [N]",
    "sweep",
    "target [Hz]",
    "realised [Hz]",
    "|F1| [N]",
    "iter.",
    "conv.",
    "error [%]",
)


def planned_steps(data: SteppedSineData) -> int | None:
    """Steps the file's plan has (None if the stored plan cannot be read)."""
    from rig.config.plans import plan_from_dict
    from rig.config.tomlconfig import ConfigError

    try:
        return plan_from_dict(data.config["plan"], f"plan stored in {data.path}").n_steps
    except (ConfigError, KeyError, TypeError):
        return None


class RunBrowser(QtWidgets.QWidget):
    """Open a measurement file and browse it.

    Signals
    -------
    resume_requested(object, object)
        (path, data): complete this unfinished run.
    workbench_requested(object)
        Path of a stepped-sine file to compare with a model.
    """

    resume_requested = QtCore.Signal(object, object)
    workbench_requested = QtCore.Signal(object)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.data: SteppedSineData | RandomData | None = None
        self.path: Path | None = None
        self.open_button = QtWidgets.QPushButton("Open file…")
        self.reload_button = QtWidgets.QPushButton("Reload")
        self.resume_button = QtWidgets.QPushButton("Complete this run…")
        self.resume_button.setToolTip("run the remaining steps of the plan into this file")
        self.workbench_button = QtWidgets.QPushButton("Compare with a model…")
        self.header = QtWidgets.QLabel("no file open")
        self.header.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.header.setWordWrap(True)
        self.header.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.channel = QtWidgets.QComboBox()
        self.channel.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToContents)
        self.steps = QtWidgets.QTableWidget(0, len(_STEP_COLUMNS))
        self.steps.setHorizontalHeaderLabels(list(_STEP_COLUMNS))
        self.steps.verticalHeader().hide()
        self.steps.setAlternatingRowColors(True)
        self.steps.horizontalHeader().setSectionResizeMode(
            QtWidgets.QHeaderView.ResizeMode.ResizeToContents
        )
        self.frf = FrfPlots()
        self.random_mag = make_plot("H1 magnitude", "frequency [Hz]", "|H1|", log_y=True)
        self.coherence = make_plot("coherence", "frequency [Hz]", "coherence [-]", legend=False)
        self.random_plots = QtWidgets.QWidget()
        rl = QtWidgets.QVBoxLayout(self.random_plots)
        rl.setContentsMargins(0, 0, 0, 0)
        rl.addWidget(self.random_mag, 3)
        rl.addWidget(self.coherence, 2)
        self.plots = QtWidgets.QStackedWidget()
        self.plots.addWidget(self.frf)
        self.plots.addWidget(self.random_plots)

        self._lay_out()
        self.open_button.clicked.connect(self._open_dialog)
        self.reload_button.clicked.connect(lambda: self.path and self.open(self.path))
        self.resume_button.clicked.connect(lambda: self.resume_requested.emit(self.path, self.data))
        self.workbench_button.clicked.connect(lambda: self.workbench_requested.emit(self.path))
        self.channel.currentIndexChanged.connect(lambda _i: self._draw())
        self._buttons()

    def _lay_out(self) -> None:
        """The buttons and the channel on top; the header and the steps beside the plots."""
        top = QtWidgets.QHBoxLayout()
        for b in (self.open_button, self.reload_button, self.resume_button, self.workbench_button):
            top.addWidget(b)
        top.addStretch(1)
        top.addWidget(QtWidgets.QLabel("channel:"))
        top.addWidget(self.channel)
        left = QtWidgets.QWidget()
        ll = QtWidgets.QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addWidget(self.header)
        ll.addWidget(self.steps, 1)
        split = QtWidgets.QSplitter()
        split.addWidget(left)
        split.addWidget(self.plots)
        split.setSizes([620, 980])
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(top)
        layout.addWidget(split, 1)

    def _buttons(self) -> None:
        stepped = isinstance(self.data, SteppedSineData)
        self.reload_button.setEnabled(self.path is not None)
        self.resume_button.setEnabled(stepped and not self.data.complete)
        self.workbench_button.setEnabled(stepped and self.data.n_steps > 0)

    def _open_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Open a measurement file", "", "HDF5 files (*.h5 *.hdf5);;All files (*)"
        )
        if name:
            self.open(name)

    def open(self, path: str | Path) -> bool:
        """Read and show a file; a file that cannot be read says why in the header."""
        path = Path(path)
        try:
            data = read_measurement(path)
        except (MeasurementFileError, OSError, ValueError) as exc:
            self.header.setText(f"<span style='color:{ALARM}'>cannot read {path}: {exc}</span>")
            return False
        self.path, self.data = path, data
        self.channel.blockSignals(True)
        self.channel.clear()
        motion = [c for c in data.channels if c.role != "drive-force"]
        for c in motion:
            self.channel.addItem(f"{c.name} (point {c.point} {c.direction})", c.name)
        self.channel.setCurrentIndex(max(len(motion) - 1, 0))
        self.channel.blockSignals(False)
        self._show_header()
        self._show_steps()
        self._draw()
        self._buttons()
        return True

    def _show_header(self) -> None:
        d = self.data
        colour = {"success": OK, "running": WARN}.get(d.exit_status, ALARM)
        chip = status_chip(d.exit_status.upper() + (" (complete)" if d.complete else ""), colour)
        plan = d.config.get("plan", {}) if isinstance(d.config, dict) else {}
        kind = "random" if isinstance(d, RandomData) else "stepped sine"
        rows = [
            f"<b>{self.path.name}</b> &nbsp; {chip}",
            f"plan <b>{plan.get('name', '?')}</b> ({kind}), created {d.created:%Y-%m-%d %H:%M} UTC",
        ]
        if isinstance(d, SteppedSineData):
            planned = planned_steps(d)
            levels = "/".join(f"{v:g}" for v in d.levels_n)
            rows.append(
                f"steps on disk: <b>{d.n_steps}</b> of {planned if planned else '?'}; levels "
                f"{levels} N; orders {', '.join(str(o) for o in d.orders)}"
            )
            if d.n_steps:
                conv = float(np.mean(d.control_converged))
                rows.append(
                    f"force control converged at {conv:.0%} of the steps, largest final error "
                    f"{float(np.max(d.control_error)):.2%}"
                )
        else:
            rows.append(
                f"H1 of {len(d.channels)} channels, {d.n_averages} averages, "
                f"{d.rms_force_n:.3g} N rms"
            )
        if d.exit_message:
            rows.append(f"ended: {d.exit_message}")
        a = d.actuator
        rows.append(
            f"drive at point {a.point} {a.direction}; channels: "
            + ", ".join(c.name for c in d.channels)
        )
        self.header.setText("<br>".join(rows))

    def _show_steps(self) -> None:
        d = self.data
        if not isinstance(d, SteppedSineData):
            self.steps.setRowCount(0)
            return
        self.steps.setRowCount(d.n_steps)
        for r in range(d.n_steps):
            cells = [
                str(int(d.plan_index[r])),
                f"{d.levels_n[d.level_index[r]]:g}",
                "up" if d.sweep_direction[r] > 0 else "down",
                f"{d.frequency_target_hz[r]:.4g}",
                f"{d.frequency_hz[r]:.4f}",
                f"{abs(d.force[r, 0]):.4g}",
                str(int(d.control_iterations[r])),
                "yes" if d.control_converged[r] else "NO",
                f"{100 * d.control_error[r]:.2f}",
            ]
            for k, text in enumerate(cells):
                item = no_edit(QtWidgets.QTableWidgetItem(text))
                item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
                if text == "NO":
                    item.setForeground(QtGui.QBrush(QtGui.QColor(ALARM)))
                self.steps.setItem(r, k, item)

    def _draw(self) -> None:
        d = self.data
        name = self.channel.currentData()
        if d is None or name is None:
            return
        ch = d.channels[d.channel_index(name)]
        if isinstance(d, SteppedSineData):
            self.plots.setCurrentWidget(self.frf)
            self.frf.configure([str(o) for o in d.orders], frf_unit(ch.quantity, ch.unit), name)
            levels = {i: float(v) for i, v in enumerate(d.levels_n)}
            colors = [color(i) for i in range(8)]
            series = sweep_series(
                d.frequency_hz, d.level_index, d.sweep_direction, d.frf(name), levels, colors
            )
            self.frf.set_series(series)
            return
        self.plots.setCurrentWidget(self.random_plots)
        h = d.frf(name)
        f = d.frequency_hz
        keep = (f > 0) & np.isfinite(h) & (np.abs(h) > 0)
        self.random_mag.getPlotItem().clear()
        self.random_mag.getPlotItem().setLabel("left", f"|H1| [{frf_unit(ch.quantity, ch.unit)}]")
        self.random_mag.plot(f[keep], np.abs(h[keep]), pen=color(0), name=name)
        self.coherence.getPlotItem().clear()
        coh = d.coherence[:, d.channel_index(name)]
        self.coherence.plot(f, coh, pen=color(1))
        self.coherence.getPlotItem().setYRange(0, 1.05)

    def step_count(self) -> int:
        """Rows shown in the steps table."""
        return self.steps.rowCount()
