"""Planning and calibration results in the workbench.

:class:`PlanningView` shows a pretest plan (:class:`analysis.planning.PlanResult`, or the JSON
that ``python -m analysis plan --json`` prints): the best configurations (the paper's Table 4),
the Cramer-Rao standard deviations of the chosen one and its correlation indices.
:class:`CalibrationView` shows a calibration result file (``calibration.json``, read by
:func:`analysis.calibration.results.load_calibration`): the parameters with their standard
deviations, the fit's chi-square and the Levenberg-Marquardt history.
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from rig.gui.heatmap import BLUES, Heatmap
from rig.gui.style import PALETTE, heading, make_plot, no_edit

__all__ = ["CalibrationView", "PlanningView"]

_TOP_COLUMNS = ("rank", "actuator", "levels [N]", "range [Hz]", "sensors", "det(FIM)", "log10 det")


def _cell(text: str) -> QtWidgets.QTableWidgetItem:
    return no_edit(QtWidgets.QTableWidgetItem(text))


class PlanningView(QtWidgets.QWidget):
    """A plan's ranking, standard deviations and correlation indices."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.candidates = QtWidgets.QComboBox()
        self.candidates.addItem("quick: levels 2/4/6 N choose 2, two ranges", "quick")
        self.candidates.addItem("the paper's 14 700 configurations", "paper")
        self.parameters = QtWidgets.QLineEdit("k_c, gap, v_c")
        self.parameters.setToolTip("model parameters to plan for")
        self.run_button = QtWidgets.QPushButton("Plan with the model")
        self.open_button = QtWidgets.QPushButton("Open plan JSON…")
        self.summary = QtWidgets.QLabel("no plan yet")
        self.summary.setWordWrap(True)
        self.top = QtWidgets.QTableWidget(0, len(_TOP_COLUMNS))
        self.top.setHorizontalHeaderLabels(list(_TOP_COLUMNS))
        self.top.verticalHeader().hide()
        self.top.horizontalHeader().setSectionResizeMode(
            QtWidgets.QHeaderView.ResizeMode.ResizeToContents
        )
        self.std = QtWidgets.QLabel("")
        self.std.setWordWrap(True)
        self.mac = Heatmap(
            "parameter correlation (MAC)",
            "correlation indices of the chosen configuration (MAC between the columns of the "
            "noise-whitened Jacobian): 1, the parameters' effects on the FRFs cannot be told "
            "apart; 0, independent",
            colours=BLUES,
        )
        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(QtWidgets.QLabel("candidates:"))
        bar.addWidget(self.candidates)
        bar.addWidget(QtWidgets.QLabel("parameters:"))
        bar.addWidget(self.parameters)
        bar.addWidget(self.run_button)
        bar.addWidget(self.open_button)
        bar.addStretch(1)
        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.summary)
        left.addWidget(heading("Best configurations by det(FIM)"))
        left.addWidget(self.top, 1)
        left.addWidget(self.std)
        body = QtWidgets.QHBoxLayout()
        body.addLayout(left, 3)
        body.addWidget(self.mac, 2)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addLayout(body, 1)
        self.result: dict | None = None

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(
            p.strip() for p in self.parameters.text().replace(";", ",").split(",") if p.strip()
        )

    def show_plan(self, result: dict) -> None:
        """Show a plan: ``PlanResult.to_dict()`` or the JSON of ``python -m analysis plan``."""
        self.result = result
        params = list(result["parameters"])
        units = list(result.get("units", [""] * len(params)))
        chosen = result["chosen"]
        self.summary.setText(
            f"{result['n_configurations']} configurations ({result['n_identifiable']} "
            f"identifiable) from {result['n_sweeps']} sweeps / {result['n_steps']} steps. "
            f"Chosen: actuator {chosen['actuator']}, levels "
            f"{'/'.join(f'{v:g}' for v in chosen['levels_n'])} N, {chosen['range_hz']} Hz, "
            f"sensors {', '.join(map(str, chosen['sensors']))}"
        )
        rows = result["top"]
        self.top.setRowCount(len(rows))
        for r, row in enumerate(rows):
            det = row.get("det")
            cells = [
                str(row["rank"]),
                str(row["actuator"]),
                ", ".join(f"{v:g}" for v in row["levels_n"]),
                str(row["range_hz"]),
                ", ".join(map(str, row["sensors"])),
                "-" if det is None else f"{det:.3g}",
                "-" if row.get("log10_det") is None else f"{row['log10_det']:.2f}",
            ]
            for k, text in enumerate(cells):
                self.top.setItem(r, k, _cell(text))
        corr = result["correlations"]
        std = corr.get("std", [])
        parts = []
        for p, u, s in zip(params, units, std, strict=False):
            parts.append(f"{p} {'-' if s is None else f'{s:.3g}'}{f' {u}' if u else ''}")
        self.std.setText(
            f"Cramer-Rao standard deviations ({corr['step_plan']} Hz, {corr['n_steps']} steps per "
            f"level): " + "; ".join(parts)
        )
        mac = np.array([[np.nan if v is None else v for v in row] for row in corr["mac"]])
        self.mac.show_values(mac, params, params, vmin=0.0, vmax=1.0, fmt="{:.3f}")


class CalibrationView(QtWidgets.QWidget):
    """A calibration result: parameters with standard deviations, chi-square, LM history."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.open_button = QtWidgets.QPushButton("Open calibration.json…")
        self.use_button = QtWidgets.QPushButton("Use the calibrated model")
        self.use_button.setToolTip("compare and diagnose with the calibrated parameter values")
        self.use_button.setEnabled(False)
        self.summary = QtWidgets.QLabel("no calibration result loaded")
        self.summary.setWordWrap(True)
        self.summary.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.table = QtWidgets.QTableWidget(0, 4)
        self.table.setHorizontalHeaderLabels(["parameter", "value", "std", "std / value"])
        self.table.verticalHeader().hide()
        self.table.horizontalHeader().setSectionResizeMode(
            QtWidgets.QHeaderView.ResizeMode.ResizeToContents
        )
        self.history = make_plot(
            "Levenberg-Marquardt history", "iteration", "cost (weighted misfit) [-]", log_y=True
        )
        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(self.open_button)
        bar.addWidget(self.use_button)
        bar.addStretch(1)
        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.summary)
        left.addWidget(self.table, 1)
        body = QtWidgets.QHBoxLayout()
        body.addLayout(left, 1)
        body.addWidget(self.history, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addLayout(body, 1)
        self.calibration = None

    def show_calibration(self, result, data_path: str, source: str) -> None:
        """Show an :class:`analysis.calibration.nonlinear.NonlinearCalibration`."""
        self.calibration = result
        std = result.std
        levels = ", ".join(f"{v:g}" for v in result.calibration_levels_n)
        held = result.validation_level_n
        self.summary.setText(
            f"<b>{source}</b><br>chi-square per degree of freedom {result.chi2_per_dof:.3g} over "
            f"{result.n_residuals} residuals; calibrated on {levels} N"
            + (f", {held:g} N kept for validation" if held else "")
            + (f"<br>measurement: {data_path}" if data_path else "")
        )
        names = list(result.parameters)
        self.table.setRowCount(len(names))
        for r, n in enumerate(names):
            v, s = result.parameters[n], std.get(n, math.nan)
            rel = abs(s / v) if v else math.nan
            for k, text in enumerate([n, f"{v:.6g}", f"{s:.3g}", f"{rel:.2%}"]):
                self.table.setItem(r, k, _cell(text))
        item = self.history.getPlotItem()
        item.clear()
        hist = result.lm.history
        if hist:
            it = np.array([h.get("iteration", i) for i, h in enumerate(hist)], dtype=float)
            cost = np.array([h["cost"] for h in hist], dtype=float)
            item.plot(
                it,
                np.maximum(cost, 1e-12),
                pen=pg.mkPen(PALETTE[0], width=2.5),
                symbol="o",
                symbolSize=7,
                symbolBrush=PALETTE[0],
                name="cost",
            )
        self.use_button.setEnabled(True)
