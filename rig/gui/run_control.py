"""Run control: the buttons, the run's state and progress, the amplifier, alarms, the pretest.

:class:`RunControls` is the strip above the live plots (pre-test, start, pause, resume, abort,
state, progress and time left); :class:`RunStatusPanel` holds the amplifier's status as its
serial driver reports it, the alarm list (warnings, faults, pauses) and the pretest's channel
checks. Neither runs anything: the acquisition panel connects the buttons to its controller.
"""

from __future__ import annotations

import datetime
import math

from PySide6 import QtCore, QtGui, QtWidgets

from rig.gui.live_data import LiveRun
from rig.gui.style import ALARM, OK, WARN, heading, no_edit, status_chip

__all__ = ["RunControls", "RunStatusPanel", "format_duration"]

_STATE_COLOURS = {
    "idle": "#666666",
    "starting": "#0072B2",
    "pretest": "#0072B2",
    "running": OK,
    "paused": WARN,
    "aborting": ALARM,
    "finished": "#444444",
    "aborted": ALARM,
    "failed": ALARM,
    "success": OK,
}
_SEVERITY_COLOURS = {"warning": WARN, "fault": ALARM, "paused": ALARM, "info": "#444444"}


def format_duration(seconds: float) -> str:
    """``h:mm:ss`` or ``m:ss`` ("-" when unknown)."""
    if not math.isfinite(seconds):
        return "-"
    s = int(round(seconds))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class RunControls(QtWidgets.QWidget):
    """Buttons, state, progress and time left."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.pretest = QtWidgets.QPushButton("Pre-test")
        self.pretest.setToolTip(
            "noise floor at 0 V, low-level loop check, every channel checked (no file written)"
        )
        self.start = QtWidgets.QPushButton("Start")
        self.pause = QtWidgets.QPushButton("Pause")
        self.pause.setToolTip("ramp the drive to 0 V at the next block and wait")
        self.resume = QtWidgets.QPushButton("Resume")
        self.abort = QtWidgets.QPushButton("Abort")
        self.abort.setToolTip("ramp the drive to 0 V and end the run; completed steps are kept")
        self.start.setStyleSheet(f"QPushButton:enabled {{ font-weight: bold; color: {OK}; }}")
        self.abort.setStyleSheet(f"QPushButton:enabled {{ font-weight: bold; color: {ALARM}; }}")
        self.state = QtWidgets.QLabel()
        self.state.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setFormat("%v of %m steps")
        self.progress.setMinimumWidth(220)
        self.step = QtWidgets.QLabel("")
        self.time_left = QtWidgets.QLabel("")
        row = QtWidgets.QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        for b in (self.pretest, self.start, self.pause, self.resume, self.abort):
            b.setMinimumWidth(78)
            row.addWidget(b)
        row.addSpacing(12)
        row.addWidget(self.state)
        row.addWidget(self.progress, 1)
        row.addWidget(self.step)
        row.addSpacing(8)
        row.addWidget(self.time_left)
        self.set_state("idle", can_start=True, can_pretest=True)

    def set_state(self, state: str, *, can_start: bool, can_pretest: bool) -> None:
        """Show a state and enable the buttons that make sense in it."""
        self.state.setText(status_chip(state.upper(), _STATE_COLOURS.get(state, "#444444")))
        idle = state in ("idle", "finished", "success", "aborted", "failed")
        self.start.setEnabled(idle and can_start)
        self.pretest.setEnabled(idle and can_pretest)
        self.pause.setEnabled(state == "running")
        self.resume.setEnabled(state == "paused")
        self.abort.setEnabled(state in ("starting", "pretest", "running", "paused"))

    def show_progress(self, live: LiveRun) -> None:
        if live.kind == "random":
            done, total = live.records
            self.progress.setFormat("%v of %m records")
        else:
            done, total = live.n_done, live.n_steps
            self.progress.setFormat("%v of %m steps")
        self.progress.setMaximum(max(total, 1))
        self.progress.setValue(min(done, max(total, 1)))
        step = live.current
        if step is not None and live.state in ("running", "paused"):
            self.step.setText(
                f"step {step.plan_index + 1}: {step.frequency_hz:.4g} Hz at {step.level_n:g} N"
            )
        elif live.state == "finished":
            message = live.message if live.status != "success" else ""
            self.step.setText(message[:90] + ("…" if len(message) > 90 else ""))
            self.step.setToolTip(message)
        left = live.time_left_s()
        self.time_left.setText(
            f"time left {format_duration(left)}" if live.state != "finished" else ""
        )


class RunStatusPanel(QtWidgets.QWidget):
    """Amplifier status, alarms and the pretest's channel checks."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.amplifier = QtWidgets.QLabel("amplifier: -")
        self.amplifier.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.amplifier.setWordWrap(True)
        self.clear_overload = QtWidgets.QPushButton("Clear overload && enable")
        self.clear_overload.setToolTip(
            "after finding the cause (level, shaker, cables): clear the amplifier's overload "
            "latch and switch its output on, then resume"
        )
        self.clear_overload.setEnabled(False)
        self.alarms = QtWidgets.QListWidget()
        self.alarms.setWordWrap(True)
        self.alarms.setAlternatingRowColors(True)
        self.pretest = QtWidgets.QTableWidget(0, 5)
        self.pretest.setHorizontalHeaderLabels(
            ["channel", "status", "noise (rms)", "loop response", "SNR"]
        )
        self.pretest.verticalHeader().hide()
        self.pretest.horizontalHeader().setSectionResizeMode(
            QtWidgets.QHeaderView.ResizeMode.ResizeToContents
        )
        self.pretest_note = QtWidgets.QLabel("")
        self.pretest_note.setWordWrap(True)
        amp_box = QtWidgets.QVBoxLayout()
        amp_box.addWidget(heading("Amplifier"))
        amp_box.addWidget(self.amplifier)
        amp_box.addWidget(self.clear_overload)
        amp_box.addStretch(1)
        alarm_box = QtWidgets.QVBoxLayout()
        alarm_box.addWidget(heading("Alarms and messages"))
        alarm_box.addWidget(self.alarms)
        pre_box = QtWidgets.QVBoxLayout()
        pre_box.addWidget(heading("Pre-test"))
        pre_box.addWidget(self.pretest)
        pre_box.addWidget(self.pretest_note)
        row = QtWidgets.QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        row.addLayout(amp_box, 2)
        row.addLayout(alarm_box, 5)
        row.addLayout(pre_box, 4)
        self._n_alarms = 0
        self._pretest = None

    def show_amplifier(self, status) -> None:
        """An :class:`~rig.instruments.amplifier.AmplifierStatus` or a sentence."""
        if isinstance(status, str):
            self.amplifier.setText(status)
            self.clear_overload.setEnabled(False)
            return
        if status.overload:
            chip = status_chip("OVERLOAD", ALARM)
        elif status.drive_ok:
            chip = status_chip("ON", OK)
        elif status.muted:
            chip = status_chip("MUTED", WARN)
        else:
            chip = status_chip("OFF", "#666666")
        self.amplifier.setText(
            f"{chip}<br>gain {status.gain_v_per_v:g} V/V<br>current {status.current_a:.3g} A"
            f"<br>heat sink {status.temperature_c:.1f} °C"
            f"<br>{'remote' if status.remote else 'local'} control"
        )
        self.clear_overload.setEnabled(status.overload)

    def show_alarms(self, live: LiveRun) -> None:
        """Append alarms not shown yet; the newest is scrolled into view."""
        if len(live.alarms) < self._n_alarms:
            self.alarms.clear()
            self._n_alarms = 0
        for a in live.alarms[self._n_alarms :]:
            when = datetime.datetime.fromtimestamp(a.time_s).strftime("%H:%M:%S")
            item = QtWidgets.QListWidgetItem(f"{when}  {a.severity}: {a.message}")
            item.setForeground(QtGui.QBrush(QtGui.QColor(_SEVERITY_COLOURS[a.severity])))
            item.setToolTip(a.message)
            self.alarms.addItem(item)
        if len(live.alarms) > self._n_alarms:
            self.alarms.scrollToBottom()
        self._n_alarms = len(live.alarms)
        self._show_pretest(live.pretest)

    def clear(self) -> None:
        self.alarms.clear()
        self._n_alarms = 0

    def _show_pretest(self, report) -> None:
        if report is self._pretest:
            return
        self._pretest = report
        if report is None:
            self.pretest.setRowCount(0)
            self.pretest_note.setText("")
            return
        self.pretest.setRowCount(len(report.channels))
        for r, c in enumerate(report.channels):
            cells = [
                c.name,
                c.status,
                f"{c.noise_rms:.3g}",
                "-" if math.isnan(c.response) else f"{c.response:.3g}",
                "-" if math.isnan(c.snr) else f"{c.snr:.0f}",
            ]
            for k, text in enumerate(cells):
                item = no_edit(QtWidgets.QTableWidgetItem(text))
                if k == 1:
                    colour = OK if c.status == "ok" else (WARN if c.status == "weak" else ALARM)
                    item.setForeground(QtGui.QBrush(QtGui.QColor(colour)))
                if c.message:
                    item.setToolTip(c.message)
                self.pretest.setItem(r, k, item)
        verdict = "all channels respond" if report.ok else report.problem_message()
        gain = ""
        if report.gain_n_per_v is not None:
            gain = "; loop gain " + ", ".join(f"{abs(g):.3g}" for g in report.gain_n_per_v) + " N/V"
            gain += f" at {report.frequency_hz:.4g} Hz"
        self.pretest_note.setText(verdict + gain)
