"""Measured against model FRFs of one channel: markers measured, lines the model.

Shows an :class:`analysis.diagnosis.Comparison` (its measured and predicted FRFs, in the
file's step order) per level and sweep, and, after an effect was added, the model before it in
grey beside the augmented one.
"""

from __future__ import annotations

from PySide6 import QtWidgets

from rig.gui.frf_view import FrfPlots, frf_unit, sweep_series
from rig.gui.style import color, legend_html

__all__ = ["ComparisonView"]

_GREY = "#999999"


class ComparisonView(QtWidgets.QWidget):
    """Channel choice and the FRFs of a comparison."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.channel = QtWidgets.QComboBox()
        self.note = QtWidgets.QLabel("")
        self.frf = FrfPlots()
        pick = QtWidgets.QHBoxLayout()
        pick.addWidget(QtWidgets.QLabel("channel:"))
        pick.addWidget(self.channel)
        pick.addWidget(self.note, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(pick)
        layout.addWidget(self.frf, 1)
        self.channel.currentIndexChanged.connect(lambda _i: self._draw())
        self.data = self.comparison = self.before = None
        self.model_label = ""

    def show_comparison(self, data, cmp, before=None, model_label: str = "model") -> None:
        """Show ``cmp`` (an :class:`analysis.diagnosis.Comparison` of ``data``); ``before`` is
        the comparison of the model before an effect was added (drawn grey)."""
        self.data, self.comparison, self.before = data, cmp, before
        self.model_label = model_label
        current = self.channel.currentText()
        self.channel.blockSignals(True)
        self.channel.clear()
        self.channel.addItems(list(cmp.channels))
        index = self.channel.findText(current)
        self.channel.setCurrentIndex(index if index >= 0 else len(cmp.channels) - 1)
        self.channel.blockSignals(False)
        self._draw()

    def _draw(self) -> None:
        cmp, d = self.comparison, self.data
        if cmp is None or d is None or self.channel.currentIndex() < 0:
            return
        c = self.channel.currentIndex()
        name = cmp.channels[c]
        ch = d.channels[d.channel_index(name)]
        self.frf.configure(cmp.orders, frf_unit(ch.quantity, ch.unit), name)
        levels = {i: float(v) for i, v in enumerate(d.levels_n)}
        colors = [color(i) for i in range(8)]
        args = (d.frequency_hz, d.level_index, d.sweep_direction)
        series = sweep_series(*args, cmp.measured[:, c, :], levels, colors, "measured", " measured")
        if self.before is not None:
            grey = [_GREY] * 8
            model = self.before.predicted[:, c, :]
            series += sweep_series(*args, model, levels, grey, "model", " model before")
        label = " model" if self.before is None else " with the effect"
        series += sweep_series(*args, cmp.predicted[:, c, :], levels, colors, "model", label)
        shown = sorted(set(d.level_index.tolist()))
        legend = legend_html([(f"{levels[i]:g} N", colors[i % 8]) for i in shown])
        legend += " &nbsp;&nbsp; ● measured &nbsp; ━ " + (
            self.model_label if self.before is None else "with the added effect"
        )
        if self.before is not None:
            legend += " &nbsp; " + legend_html([("the model before", _GREY)], marker="━")
        self.frf.set_series(series, legend)
        self.note.setText(f"residual {cmp.rms_over_noise:.3g} x noise")
