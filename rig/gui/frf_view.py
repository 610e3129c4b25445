"""Multi-harmonic FRF plots: magnitude and phase of every order, one column per order.

Each column is a Bode plot: the magnitude above the phase on one frequency axis, labelled
(ticks and title, with its unit) under the phase; the y axes have the same width in every
column, and each plot keeps room for its titles and a data area however small the grid.

Used live (the FRFs growing step by step), by the run browser (a file's FRFs) and by the
workbench (measured against model). A series is one curve in every column: a sweep at one
level, measured or predicted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from rig.gui.style import legend_html, make_plot

__all__ = ["FrfPlots", "FrfSeries", "frf_unit", "sweep_series"]

#: Width of the y axes (tick labels and title), the same in every column [px].
_LEFT_AXIS_PX = 62
#: Least height of a plot's data area [px].
_MIN_VIEW_PX = 48

_QUANTITY_UNITS = {"acceleration": "(m/s²)/N", "velocity": "(m/s)/N", "displacement": "m/N"}


def frf_unit(quantity: str, unit: str = "") -> str:
    """Unit of an FRF of a channel measuring ``quantity`` (in ``unit``) per newton."""
    if quantity in _QUANTITY_UNITS:
        return _QUANTITY_UNITS[quantity]
    return f"{unit}/N" if unit else "1/N"


@dataclass(frozen=True)
class FrfSeries:
    """One curve in every order's column.

    Attributes
    ----------
    name : str
        Legend entry.
    frequency_hz : ndarray, shape (n,)
        Fundamental frequency of each point [Hz].
    frf : ndarray, shape (n, H), complex
        FRF of each order (points in the order they are drawn).
    color : str
    style : {"measured", "model"}
        Measured: markers joined by a thin line; model: a line.
    """

    name: str
    frequency_hz: np.ndarray
    frf: np.ndarray
    color: str
    style: str = "measured"


def sweep_series(
    frequency_hz: np.ndarray,
    level_index: np.ndarray,
    sweep_direction: np.ndarray,
    frf: np.ndarray,
    levels_n: dict[int, float],
    colors: Sequence[str],
    style: str = "measured",
    suffix: str = "",
) -> list[FrfSeries]:
    """One series per level and sweep direction, points in measured order."""
    out = []
    both = len(set(np.asarray(sweep_direction).tolist())) > 1
    for i, lv in enumerate(sorted(set(np.asarray(level_index).tolist()))):
        for d in (1, -1):
            rows = np.flatnonzero((level_index == lv) & (sweep_direction == d))
            if rows.size == 0:
                continue
            level = levels_n.get(lv)
            name = f"{level:g} N" if level is not None else f"level {lv + 1}"
            if both:
                name += " up" if d > 0 else " down"
            out.append(
                FrfSeries(
                    name + suffix,
                    np.asarray(frequency_hz)[rows],
                    np.asarray(frf)[rows],
                    colors[i % len(colors)],
                    style,
                )
            )
    return out


class FrfPlots(QtWidgets.QWidget):
    """Magnitude (top row, log scale) and phase (bottom row) of each order's FRF."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.legend = QtWidgets.QLabel("")
        self.legend.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self._grid = QtWidgets.QGridLayout()
        self._grid.setContentsMargins(0, 0, 0, 0)
        self._grid.setHorizontalSpacing(4)
        self._grid.setVerticalSpacing(0)  # magnitude and phase: one plot
        outer = QtWidgets.QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        outer.setSpacing(2)
        outer.addWidget(self.legend)
        outer.addLayout(self._grid, 1)
        self._orders: list[str] = []
        self._unit = ""
        self._channel = ""
        self.magnitude: list[pg.PlotWidget] = []
        self.phase: list[pg.PlotWidget] = []
        self.configure(["1", "2", "3"], "(m/s²)/N", "")

    def configure(self, orders: Sequence[str], unit: str, channel: str) -> None:
        """Columns for ``orders``; the FRF's unit and the channel's name for the titles."""
        orders = [str(o) for o in orders]
        if orders == self._orders and unit == self._unit and channel == self._channel:
            return
        self._orders, self._unit, self._channel = orders, unit, channel
        for w in self.magnitude + self.phase:
            self._grid.removeWidget(w)
            w.hide()
            w.deleteLater()
        self.magnitude, self.phase = [], []
        of = f" of {channel}" if channel else ""
        for k, order in enumerate(orders):
            # magnitude above phase on one frequency axis: its ticks and title are the phase's
            mag = make_plot(
                f"order {order}: |H|{of}",
                "",
                f"|H| [{unit}]",
                log_y=True,
                legend=False,
                x_values=False,
            )
            ph = make_plot("", "fundamental frequency [Hz]", "phase [deg]", legend=False)
            ph.getPlotItem().setTitle(None)
            ph.getPlotItem().setYRange(-180, 180, padding=0.02)
            left = ph.getPlotItem().getAxis("left")
            left.setTicks([[(v, str(v)) for v in (-180, -90, 0, 90, 180)]])
            ph.setXLink(mag)
            for plot in (mag, ph):  # the same width in every column: the curves line up
                plot.getPlotItem().getAxis("left").setWidth(_LEFT_AXIS_PX)
                item = plot.getPlotItem()
                hint = item.effectiveSizeHint(QtCore.Qt.SizeHint.MinimumSize)
                title = item.getAxis("left").label.boundingRect().width()  # drawn upright
                view = max(_MIN_VIEW_PX, int(title) + 4)
                plot.setMinimumHeight(int(hint.height()) + view)
            self._grid.addWidget(mag, 0, k)
            self._grid.addWidget(ph, 1, k)
            self.magnitude.append(mag)
            self.phase.append(ph)
        self._grid.setRowStretch(0, 4)
        self._grid.setRowStretch(1, 3)

    def clear(self) -> None:
        for w in self.magnitude + self.phase:
            w.getPlotItem().clear()
        self.legend.setText("")

    def set_series(self, series: Sequence[FrfSeries], legend: str | None = None) -> None:
        """Draw the series (replacing what is drawn); ``legend`` (rich text) replaces the one
        made from the series' names."""
        self.clear()
        items, seen = [], set()
        for s in series:
            key = (s.name, s.color, s.style)
            if key not in seen and np.asarray(s.frf).size:
                seen.add(key)
                items.append((s.name, s.color, s.style))
        self.legend.setText(
            legend
            if legend is not None
            else " &nbsp; ".join(
                legend_html([(n, c)], marker="●" if st == "measured" else "━") for n, c, st in items
            )
        )
        for s in series:
            h = np.asarray(s.frf)
            if h.ndim != 2 or h.shape[0] == 0:
                continue
            f = np.asarray(s.frequency_hz, dtype=float)
            for k in range(min(h.shape[1], len(self.magnitude))):
                mag = np.abs(h[:, k])
                phase = np.degrees(np.angle(h[:, k]))
                good = np.isfinite(mag) & (mag > 0)
                kw = self._style(s)
                self.magnitude[k].plot(f[good], mag[good], **kw)
                self.phase[k].plot(f[good], phase[good], **kw)

    @staticmethod
    def _style(s: FrfSeries) -> dict:
        if s.style == "model":
            kw = {"pen": pg.mkPen(s.color, width=2.5)}
        else:
            kw = {
                "pen": pg.mkPen(s.color, width=1),
                "symbol": "o",
                "symbolSize": 6,
                "symbolBrush": pg.mkBrush(s.color),
                "symbolPen": pg.mkPen(s.color),
            }
        return kw
