"""An annotated heatmap: coloured cells with their value written in, labelled rows and columns.

Used for residual maps (residual over noise by sensor, order and level) and correlation
matrices (MAC between parameters). Values are coloured on a linear or logarithmic scale;
every cell also shows its number, so the map reads without a colour bar.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyqtgraph as pg
from PySide6 import QtGui, QtWidgets

from rig.gui.style import FONT_PT

__all__ = ["BLUES", "REDS", "Heatmap"]

#: white (good) to dark red (bad)
REDS = ((255, 255, 255), (253, 212, 158), (239, 101, 72), (153, 0, 13), (80, 0, 5))
#: white to dark blue (a neutral scale, e.g. for correlations)
BLUES = ((255, 255, 255), (198, 219, 239), (107, 174, 214), (33, 113, 181), (8, 48, 107))


class Heatmap(QtWidgets.QWidget):
    """A grid of coloured, annotated cells.

    Parameters
    ----------
    title : str
    caption : str
        A line under the map saying what the colours mean.
    colours : sequence of (r, g, b)
        The colour scale from the lowest to the highest value (:data:`REDS`, :data:`BLUES`).
    """

    def __init__(self, title: str, caption: str = "", colours=REDS, parent=None) -> None:
        super().__init__(parent)
        self.colours = tuple(colours)
        self.plot = pg.PlotWidget()
        item = self.plot.getPlotItem()
        item.setTitle(title, size=f"{FONT_PT + 1}pt")
        item.invertY(True)
        item.setMouseEnabled(False, False)
        item.hideButtons()
        for name in ("bottom", "left"):
            axis = item.getAxis(name)
            font = QtGui.QFont()
            font.setPointSize(FONT_PT - 1)
            axis.setStyle(tickFont=font, tickLength=0)
        self.image = pg.ImageItem()
        item.addItem(self.image)
        self.caption = QtWidgets.QLabel(caption)
        self.caption.setWordWrap(True)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.plot, 1)
        layout.addWidget(self.caption)
        self._texts: list[pg.TextItem] = []
        self.values = np.zeros((0, 0))

    def show_values(
        self,
        values: np.ndarray,
        rows: Sequence[str],
        columns: Sequence[str],
        *,
        vmin: float,
        vmax: float,
        log: bool = False,
        fmt: str = "{:.3g}",
        x_label: str = "",
        y_label: str = "",
    ) -> None:
        """Draw ``values`` (shape (n_rows, n_columns); NaN cells stay grey)."""
        values = np.asarray(values, dtype=float)
        self.values = values
        item = self.plot.getPlotItem()
        for t in self._texts:
            item.removeItem(t)
        self._texts = []
        if values.size == 0:
            self.image.clear()
            return
        scaled = np.log10(np.clip(values, vmin, vmax)) if log else np.clip(values, vmin, vmax)
        lo, hi = (np.log10(vmin), np.log10(vmax)) if log else (vmin, vmax)
        frac = (scaled - lo) / (hi - lo)
        rgb = self._colours(frac, self.colours)
        rgb[~np.isfinite(values)] = (220, 220, 220)
        self.image.setImage(np.transpose(rgb, (1, 0, 2)), levels=(0, 255))
        self.image.setRect(0, 0, values.shape[1], values.shape[0])
        bottom, left = item.getAxis("bottom"), item.getAxis("left")
        bottom.setTicks([[(j + 0.5, str(c)) for j, c in enumerate(columns)]])
        left.setTicks([[(i + 0.5, str(r)) for i, r in enumerate(rows)]])
        item.setLabel("bottom", x_label)
        item.setLabel("left", y_label)
        font = QtGui.QFont()
        font.setPointSize(FONT_PT - 1 if values.shape[1] < 14 else FONT_PT - 2)
        for i in range(values.shape[0]):
            for j in range(values.shape[1]):
                v = values[i, j]
                if not np.isfinite(v):
                    continue
                dark = frac[i, j] > 0.55
                text = pg.TextItem(fmt.format(v), color="w" if dark else "k", anchor=(0.5, 0.5))
                text.setFont(font)
                text.setPos(j + 0.5, i + 0.5)
                item.addItem(text)
                self._texts.append(text)
        item.setXRange(0, values.shape[1], padding=0)
        item.setYRange(0, values.shape[0], padding=0)

    @staticmethod
    def _colours(frac: np.ndarray, colours) -> np.ndarray:
        stops = np.linspace(0, 1, len(colours))
        table = np.array(colours, dtype=float)
        f = np.nan_to_num(np.clip(frac, 0, 1))
        out = np.empty(f.shape + (3,), dtype=np.ubyte)
        for c in range(3):
            out[..., c] = np.interp(f, stops, table[:, c]).astype(np.ubyte)
        return out
