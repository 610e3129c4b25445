"""The GUI's look: fonts, colours, and plots with labelled axes and legends.

Plots are pyqtgraph ``PlotWidget`` s on a white background. Axis labels carry their unit in
brackets and pyqtgraph's automatic SI prefixes are off (``mm/s^2/N`` would read as a different
quantity than the file's ``(m/s^2)/N``). Colours follow the Okabe-Ito palette, which stays
distinguishable for colour-blind readers.
"""

from __future__ import annotations

import math

import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

__all__ = [
    "ALARM",
    "FONT_PT",
    "OK",
    "PALETTE",
    "WARN",
    "color",
    "configure_app",
    "fit_bottom_axis",
    "LogAxis",
    "heading",
    "legend_html",
    "make_plot",
    "monospace",
    "no_edit",
    "status_chip",
]

FONT_PT = 10
PALETTE = (
    "#0072B2",  # blue
    "#D55E00",  # vermilion
    "#009E73",  # green
    "#CC79A7",  # purple
    "#E69F00",  # orange
    "#56B4E9",  # sky blue
    "#000000",  # black
    "#F0E442",  # yellow
)
OK, WARN, ALARM = "#1b7f3b", "#b36b00", "#c0262d"
#: Labelled mantissas of a logarithmic axis, densest first.
LOG_STEPS = ((1, 1.5, 2, 3, 5, 7), (1, 2, 5), (1,))
#: Room a tick label of a horizontal axis needs (``0.0002`` or ``1e-05`` and a gap), px.
LABEL_PX = 56


def color(i: int) -> str:
    """The ``i``-th colour of the palette (cycling)."""
    return PALETTE[i % len(PALETTE)]


def configure_app(app: QtWidgets.QApplication) -> None:
    """Application-wide font and pyqtgraph defaults."""
    font = app.font()
    font.setPointSize(FONT_PT)
    app.setFont(font)
    pg.setConfigOptions(background="w", foreground="k", antialias=True)


class LogAxis(pg.AxisItem):
    """A logarithmic axis labelled at 1, 2 and 5 times powers of ten in plain numbers (0.5, 20,
    1e+03), with unlabelled ticks between: pyqtgraph's own labels crowd on a short axis. A
    horizontal axis labels only the powers of ten where its labels, side by side, would touch."""

    def tickValues(self, minVal, maxVal, size):  # noqa: N802, N803 - pyqtgraph's names
        if not self.logMode or not (math.isfinite(minVal) and math.isfinite(maxVal)):
            return super().tickValues(minVal, maxVal, size)
        lo, hi = sorted((minVal, maxVal))
        decades = range(math.floor(lo), math.ceil(hi) + 1)
        span = hi - lo
        choice = 2 if span > 3 else 1 if span > 0.8 else 0
        if self.orientation in ("top", "bottom") and size > 0:
            per_decade = size / max(span, 1e-12)
            last = 2 if span > 1 else 1  # below a decade, powers of ten alone may miss it
            while choice < last and per_decade * _closest(LOG_STEPS[choice]) < LABEL_PX:
                choice += 1
        steps = LOG_STEPS[choice]
        major = [math.log10(m) + d for d in decades for m in steps]
        minor = [math.log10(m) + d for d in decades for m in range(2, 10)] if span <= 4 else []
        major = [v for v in major if lo <= v <= hi]
        minor = [v for v in minor if lo <= v <= hi and all(abs(v - w) > 1e-9 for w in major)]
        return [(1.0, major), (0.1, minor)]

    def tickStrings(self, values, scale, spacing):  # noqa: N802 - pyqtgraph's name
        if not self.logMode:
            return super().tickStrings(values, scale, spacing)
        if spacing != 1.0:
            return ["" for _ in values]
        return [f"{10.0**v:.3g}" for v in values]


def _closest(steps: tuple) -> float:
    """The smallest gap, in decades, between labelled mantissas ``steps`` of a log axis."""
    marks = [math.log10(m) for m in steps] + [1.0]
    return min(b - a for a, b in zip(marks, marks[1:], strict=False))


def _axis_font() -> QtGui.QFont:
    font = QtGui.QFont()
    font.setPointSize(FONT_PT - 1)
    return font


def make_plot(
    title: str,
    x_label: str,
    y_label: str,
    *,
    log_y: bool = False,
    log_x: bool = False,
    legend: bool = True,
    x_values: bool = True,
    parent: QtWidgets.QWidget | None = None,
) -> pg.PlotWidget:
    """A plot with a title, axis labels (units in brackets), a grid and a legend.

    Parameters
    ----------
    title : str
    x_label, y_label : str
        E.g. ``"frequency [Hz]"``.
    log_y, log_x : bool
        Logarithmic y, x axis (an item without log mode of its own, such as an
        ``ErrorBarItem``, then takes log10 coordinates).
    legend : bool
        Add a legend (curves with a ``name`` appear in it).
    x_values : bool
        Label the x ticks (False for a plot whose x axis is the one of the plot below it).
    """
    pg.setConfigOptions(background="w", foreground="k", antialias=True)
    axes = {}
    if log_y:
        axes["left"] = LogAxis(orientation="left")
    if log_x:
        axes["bottom"] = LogAxis(orientation="bottom")
    w = pg.PlotWidget(parent=parent, axisItems=axes or None)
    item = w.getPlotItem()
    item.setTitle(title, size=f"{FONT_PT + 1}pt")
    style = {"font-size": f"{FONT_PT}pt"}
    item.setLabel("bottom", x_label, **style)
    item.setLabel("left", y_label, **style)
    for name in ("bottom", "left"):
        axis = item.getAxis(name)
        axis.enableAutoSIPrefix(False)
        axis.setStyle(tickFont=_axis_font())
    fit_bottom_axis(w, values=x_values)
    item.showGrid(x=True, y=True, alpha=0.25)
    if log_x or log_y:
        item.setLogMode(log_x, log_y)
    if legend:
        leg = item.addLegend(offset=(-8, 8), labelTextSize=f"{FONT_PT - 1}pt")
        leg.setBrush(pg.mkBrush(255, 255, 255, 200))
        leg.setPen(pg.mkPen("#999999"))
    w.setMinimumSize(220, 160)
    return w


def fit_bottom_axis(plot: pg.PlotWidget, *, values: bool = True) -> None:
    """Make the x axis tall enough for its tick labels and its whole title.

    pyqtgraph reserves 80 % of the title's height and sets the title 5 px below the axis, so
    a title in a short plot loses its lower part; this fixes the axis height from the fonts
    (tick labels, their offset, the whole title) and keeps a margin below it for the nudge.
    """
    item = plot.getPlotItem()
    axis = item.getAxis("bottom")
    axis.setStyle(showValues=values)
    height = max(0, axis.style["tickLength"])
    if values:
        font = axis.style.get("tickFont") or _axis_font()
        height += QtGui.QFontMetrics(font).height() + axis.style["tickTextOffset"][1] + 2
    if axis.label.isVisible() and axis.labelText:
        height += axis.label.boundingRect().height()
    axis.setHeight(max(int(math.ceil(height)), 4))
    item.setContentsMargins(6, 2, 8, 6)  # the titles' nudge, the last tick label


def legend_html(items, marker: str = "■") -> str:
    """Rich text of a legend: a coloured marker and a name per ``(name, colour)`` item."""
    return " &nbsp; ".join(
        f"<span style='color:{c}; font-size:{FONT_PT + 3}pt'>{marker}</span>&nbsp;{name}"
        for name, c in items
    )


def heading(text: str) -> QtWidgets.QLabel:
    """A bold section heading."""
    label = QtWidgets.QLabel(text)
    font = label.font()
    font.setBold(True)
    font.setPointSize(FONT_PT + 1)
    label.setFont(font)
    return label


def status_chip(text: str, colour: str) -> str:
    """Rich text: ``text`` in bold on a coloured background (a state indicator)."""
    return (
        f"<span style='background-color:{colour}; color:white; font-weight:bold; "
        f"padding:2px 6px;'>&nbsp;{text}&nbsp;</span>"
    )


def monospace() -> QtGui.QFont:
    """A fixed-width font for summaries and tables of numbers."""
    font = QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont)
    font.setPointSize(FONT_PT - 1)
    return font


def no_edit(item: QtWidgets.QTableWidgetItem) -> QtWidgets.QTableWidgetItem:
    """A read-only table cell."""
    item.setFlags(item.flags() & ~QtCore.Qt.ItemFlag.ItemIsEditable)
    return item
