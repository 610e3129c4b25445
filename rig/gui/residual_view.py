"""Residual maps of a model against a run: where, in which order and at which level it fails.

The map shows the root of the chi-square per degree of freedom (1 = at the noise) by sensor,
order and level (:meth:`analysis.diagnosis.Comparison.map_sensor_order_level`); beside it,
every step's residual of one sensor and order against frequency, one curve per level. The
failing blocks of the comparison are listed with their verdicts.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6 import QtWidgets

from rig.gui.heatmap import Heatmap
from rig.gui.style import color, legend_html, make_plot, monospace

__all__ = ["ResidualView"]


class ResidualView(QtWidgets.QWidget):
    """Residual map, residual by step, failing blocks."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.map = Heatmap(
            "residual / noise",
            "each cell: root of chi-square per degree of freedom of the FRF residuals "
            "(1 = at the noise); white is good, dark red fails",
        )
        self.sensor = QtWidgets.QComboBox()
        self.order = QtWidgets.QComboBox()
        self.by_step = make_plot(
            "residual by step",
            "fundamental frequency [Hz]",
            "|model - measured| / sigma [-]",
            log_y=True,
            legend=False,
        )
        self.blocks = QtWidgets.QPlainTextEdit()
        self.blocks.setReadOnly(True)
        self.blocks.setFont(monospace())
        self.blocks.setMaximumHeight(150)
        pick = QtWidgets.QHBoxLayout()
        pick.addWidget(QtWidgets.QLabel("sensor:"))
        pick.addWidget(self.sensor)
        pick.addWidget(QtWidgets.QLabel("order:"))
        pick.addWidget(self.order)
        pick.addStretch(1)
        right = QtWidgets.QVBoxLayout()
        right.addLayout(pick)
        right.addWidget(self.by_step, 1)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(self.map, 1)
        top.addLayout(right, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(top, 1)
        layout.addWidget(self.blocks)
        self.sensor.currentIndexChanged.connect(lambda _i: self._draw_steps())
        self.order.currentIndexChanged.connect(lambda _i: self._draw_steps())
        self.comparison = None

    def show_comparison(self, cmp, title: str = "") -> None:
        """Show an :class:`analysis.diagnosis.Comparison`."""
        self.comparison = cmp
        grid, levels = cmp.map_sensor_order_level()
        rms = np.sqrt(grid)  # (channels, orders, levels)
        n_c, n_o, n_l = rms.shape
        values = rms.reshape(n_c, n_o * n_l)
        columns = [f"{o}: {lv:g} N" for o in cmp.orders for lv in levels]
        head = f"{title}: " if title else ""
        self.map.plot.getPlotItem().setTitle(
            f"{head}residual / noise (overall {cmp.rms_over_noise:.3g})"
        )
        self.map.show_values(
            values,
            cmp.channels,
            columns,
            vmin=0.5,
            vmax=300.0,
            log=True,
            x_label="order: level",
            y_label="sensor",
        )
        for combo, items in ((self.sensor, cmp.channels), (self.order, cmp.orders)):
            current = combo.currentText()
            combo.blockSignals(True)
            combo.clear()
            combo.addItems(list(items))
            combo.setCurrentIndex(max(combo.findText(current), 0) if current else len(items) - 1)
            combo.blockSignals(False)
        self.order.setCurrentIndex(0)
        self._draw_steps()
        self.blocks.setPlainText(cmp.summary(12))

    def _draw_steps(self) -> None:
        cmp = self.comparison
        item = self.by_step.getPlotItem()
        item.clear()
        if cmp is None or self.sensor.currentIndex() < 0 or self.order.currentIndex() < 0:
            return
        c, k = self.sensor.currentIndex(), self.order.currentIndex()
        r = np.abs(cmp.residual[:, c, k])
        levels = sorted(set(cmp.level_n.tolist()))
        for i, lv in enumerate(levels):
            rows = np.flatnonzero((cmp.level_n == lv) & np.isfinite(r) & (r > 0))
            if rows.size == 0:
                continue
            rows = rows[np.argsort(cmp.frequency_hz[rows], kind="stable")]
            item.plot(
                cmp.frequency_hz[rows],
                r[rows],
                pen=pg.mkPen(color(i), width=1.5),
                symbol="o",
                symbolSize=6,
                symbolBrush=color(i),
            )
        item.addLine(y=0.0, pen=pg.mkPen("#1b7f3b", width=1.5, style=pg.QtCore.Qt.DashLine))
        names = [(f"{lv:g} N", color(i)) for i, lv in enumerate(levels)]
        item.setTitle(
            f"{cmp.channels[c]}, order {cmp.orders[k]}: "
            + legend_html([*names, ("the noise", "#1b7f3b")])
        )
