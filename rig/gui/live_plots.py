"""The live plots of the acquisition window: time traces, FRFs growing, controller convergence.

:class:`LivePlots` redraws from a :class:`~rig.gui.live_data.LiveRun` and the controller's
newest samples when the window's redraw timer asks (a few times a second, whatever the event
rate), and only what changed.
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6 import QtWidgets

from rig.gui.frf_view import FrfPlots, frf_unit, sweep_series
from rig.gui.live_data import LiveRun
from rig.gui.sample_tap import TimeTraces
from rig.gui.style import ALARM, OK, PALETTE, color, legend_html, make_plot

__all__ = ["ConvergencePlots", "LivePlots", "TimeTracePlots"]


class TimeTracePlots(QtWidgets.QWidget):
    """The newest samples: drive force (top) and responses (bottom) against time."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.force = make_plot(
            "drive force (newest samples)", "time [s]", "force [N]", legend=False
        )
        self.response = make_plot(
            "responses (newest samples)", "time [s]", "acceleration [m/s²]", legend=False
        )
        self.response.setXLink(self.force)
        for plot in (self.force, self.response):  # many samples: draw what the pixels show
            plot.getPlotItem().setDownsampling(auto=True, mode="peak")
            plot.getPlotItem().setClipToView(True)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.force)
        layout.addWidget(self.response)
        self._curves: dict[str, pg.PlotDataItem] = {}
        self._names: tuple[str, ...] = ()

    def show_traces(self, traces: TimeTraces | None, period_s: float = math.nan) -> None:
        """Draw the newest samples (the last four periods when the period is known)."""
        if traces is None:
            return
        if traces.names != self._names:
            self._setup_curves(traces)
        keep = traces.time_s >= -4.0 * period_s if math.isfinite(period_s) else slice(None)
        t = traces.time_s[keep]
        for c, name in enumerate(traces.names):
            self._curves[name].setData(t, traces.data[keep, c])

    def _setup_curves(self, traces: TimeTraces) -> None:
        for plot in (self.force, self.response):
            plot.getPlotItem().clear()
        self._curves = {}
        k = 0
        forces, responses = [], []
        for name, unit in zip(traces.names, traces.units, strict=True):
            if unit == "N":
                plot, colour = self.force, PALETTE[6]
                forces.append((name, colour))
            else:
                plot, colour = self.response, color(k)
                responses.append((name, colour))
                k += 1
            self._curves[name] = plot.plot(pen=pg.mkPen(colour, width=1.5), antialias=False)
        self._names = traces.names
        self.force.getPlotItem().setTitle(f"drive force (newest samples): {legend_html(forces)}")
        self.response.getPlotItem().setTitle(
            f"responses (newest samples): {legend_html(responses)}"
        )


class ConvergencePlots(QtWidgets.QWidget):
    """Force control: the error at every iteration of the step under way (and the previous
    one), and the iterations every finished step took."""

    def __init__(self, tolerance: float = 0.01, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.error = make_plot(
            "force control error",
            "iteration",
            "max|F - T| / |T1| [-]",
            log_y=True,
            legend=False,
        )
        self.steps = make_plot(
            legend_html([("converged", OK), ("not converged", ALARM)]),
            "step (plan index)",
            "iterations",
            legend=False,
        )
        self.tolerance = tolerance
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.error)
        layout.addWidget(self.steps)

    def show_run(self, live: LiveRun) -> None:
        item = self.error.getPlotItem()
        item.clear()
        tol = self.tolerance
        if live.last_iterations:
            it = np.array([i for i, _, _ in live.last_iterations])
            err = np.array([e for _, e, _ in live.last_iterations])
            item.plot(
                it,
                np.maximum(err, 1e-6),
                pen=pg.mkPen("#aaaaaa", width=1.5),
                symbol="o",
                symbolSize=5,
                symbolBrush="#aaaaaa",
            )
        if live.iterations:
            it = np.array([i for i, _, _ in live.iterations])
            err = np.array([e for _, e, _ in live.iterations])
            item.plot(
                it,
                np.maximum(err, 1e-6),
                pen=pg.mkPen(PALETTE[0], width=2.5),
                symbol="o",
                symbolSize=7,
                symbolBrush=PALETTE[0],
            )
        step = live.current
        label = "this step"
        if step is not None:
            label = f"{step.frequency_hz:.4g} Hz, {step.level_n:g} N"
        item.setTitle(
            legend_html([(label, PALETTE[0]), ("previous", "#aaaaaa"), (f"tol. {tol:.0%}", OK)])
        )
        item.addLine(y=math.log10(tol), pen=pg.mkPen(OK, width=1.5, style=pg.QtCore.Qt.DashLine))
        steps = self.steps.getPlotItem()
        steps.clear()
        if live.steps:
            x = np.array([s.plan_index for s in live.steps])
            n = np.array([s.iterations for s in live.steps])
            ok = np.array([s.converged for s in live.steps])
            for mask, colour in ((ok, OK), (~ok, ALARM)):
                if mask.any():
                    steps.addItem(
                        pg.BarGraphItem(
                            x=x[mask], height=n[mask], width=0.7, brush=colour, pen=pg.mkPen(colour)
                        )
                    )


class LivePlots(QtWidgets.QWidget):
    """The acquisition window's plots, redrawn from a :class:`LiveRun` on request."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.frf = FrfPlots()
        self.traces = TimeTracePlots()
        self.convergence = ConvergencePlots()
        self.channel = QtWidgets.QComboBox()
        self.channel.setToolTip("response channel whose FRFs are drawn")
        self.channel.currentIndexChanged.connect(lambda _i: self._force_redraw())
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("FRF of channel:"))
        top.addWidget(self.channel)
        top.addStretch(1)
        lower = QtWidgets.QHBoxLayout()
        lower.addWidget(self.traces, 4)
        lower.addWidget(self.convergence, 3)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(top)
        layout.addWidget(self.frf, 5)
        layout.addLayout(lower, 4)
        self._drawn = -1
        self._channels: tuple[str, ...] = ()
        self._quantities: dict[str, tuple[str, str]] = {}
        self._orders: list[str] = ["1", "2", "3"]

    def prepare(self, channels, orders, tolerance: float) -> None:
        """Channels of the run (``rig.config.setup.ChannelSetup``), the plan's orders and the
        controller's amplitude tolerance (drawn as a line)."""
        names = tuple(c.name for c in channels)
        self._quantities = {c.name: (c.quantity, c.unit) for c in channels}
        self._orders = [str(o) for o in orders]
        self.convergence.tolerance = tolerance
        if names != self._channels:
            self._channels = names
            self.channel.blockSignals(True)
            self.channel.clear()
            responses = [c for c in channels if c.role != "drive-force"]
            for c in responses:
                self.channel.addItem(f"{c.name} (point {c.point} {c.direction})", c.name)
            if responses:
                self.channel.setCurrentIndex(len(responses) - 1)
            self.channel.blockSignals(False)
        self._configure_frf()
        self._drawn = -1

    def _configure_frf(self) -> None:
        name = self.channel.currentData() or ""
        quantity, unit = self._quantities.get(name, ("acceleration", "m/s^2"))
        self.frf.configure(self._orders, frf_unit(quantity, unit), name)

    def _force_redraw(self) -> None:
        self._configure_frf()
        self._drawn = -1

    def redraw(self, live: LiveRun, traces: TimeTraces | None) -> None:
        """Redraw what changed since the last call."""
        period = math.nan
        if live.current is not None and live.state == "running":
            period = 1.0 / live.current.frequency_hz
        self.traces.show_traces(traces, period)
        if live.revision == self._drawn:
            return
        self._drawn = live.revision
        self.convergence.show_run(live)
        name = self.channel.currentData()
        if name and name in live.channel_names:
            c = live.channel_names.index(name)
            f, lv, sweep, h = live.frf(c)
            colors = [color(i) for i in range(8)]
            self.frf.set_series(sweep_series(f, lv, sweep, h, live.levels_n(), colors))
        elif not live.steps:
            self.frf.clear()
