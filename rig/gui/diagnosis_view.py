"""A diagnosis in the workbench: the verdict, the evidence, the ranked candidates, and the
error falling while the chosen effect is added and everything recalibrated. When nothing in the
library explains the misfit, what the data show about the missing law: its reading in words and
its equivalent stiffness and damping against the amplitude.

Shows :class:`analysis.diagnosis.Diagnosis` and :class:`analysis.diagnosis.AugmentResult` as
they are (their own summaries, numbers and words); nothing is recomputed here.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from analysis.events import Event, Iteration
from rig.gui.style import (
    ALARM,
    FONT_PT,
    OK,
    PALETTE,
    WARN,
    color,
    heading,
    legend_html,
    make_plot,
    no_edit,
    status_chip,
)

__all__ = ["DiagnosisView"]

_VERDICTS = {
    "adequate": (OK, "the model is adequate: its residual is at the noise; nothing is claimed"),
    "explained": (OK, "explained by an effect of the element library"),
    "unexplained": (ALARM, "nothing in the element library explains the misfit"),
}
_RANK_COLUMNS = ("rank", "group", "candidate", "residual / noise", "ΔBIC", "parameters")


def _parameters(values: dict) -> str:
    return ", ".join(f"{k} {v:.4g}" for k, v in values.items())


def _same_to_the_structure(location) -> str:
    """Where a place has look-alikes: the data cannot tell an element there from one at
    them, so the ranking's one place stands for all of them."""
    return (
        f"{location.name} moves as {', '.join(location.moves_as)}: an element at any of these "
        "is the same to this structure"
    )


def _label(plot: pg.PlotWidget, side: str, text: str) -> None:
    plot.getPlotItem().setLabel(side, text, **{"font-size": f"{FONT_PT}pt"})


def _draw_describing_function(plot: pg.PlotWidget, ro, y, sigma, bins, fit) -> None:
    """One describing function of a read-out against the amplitude, as the report's figure
    draws it: the steps read (a colour per level) and their binned means, each with one
    standard error, and the fit where its slope is resolved. The y range follows the binned
    means: a step whose force is mostly noise would otherwise flatten the rest."""
    item = plot.getPlotItem()
    item.clear()
    item.enableAutoRange()
    seen = np.asarray(ro.seen, bool) & np.isfinite(y) & np.isfinite(sigma)
    A = np.asarray(ro.amplitude, float)
    for i, lv in enumerate(sorted(set(ro.level_n[seen].tolist()))):
        at = seen & (ro.level_n == lv)
        pen = pg.mkPen(color(i), width=1)
        # an ErrorBarItem has no log mode of its own: its x is log10 of the amplitude
        item.addItem(pg.ErrorBarItem(x=np.log10(A[at]), y=y[at], height=2 * sigma[at], pen=pen))
        item.plot(A[at], y[at], pen=None, symbol="o", symbolSize=5, symbolBrush=color(i))
    if bins is not None and len(bins.A):
        black = pg.mkPen("#000000", width=1.5)
        item.addItem(
            pg.ErrorBarItem(x=np.log10(bins.A), y=bins.y, height=2 * bins.sigma, pen=black)
        )
        item.plot(bins.A, bins.y, pen=None, symbol="s", symbolSize=8, symbolBrush="#000000")
        lo = float(np.min(bins.y - 3 * bins.sigma))
        hi = float(np.max(bins.y + 3 * bins.sigma))
        if seen.any():
            lo = min(lo, float(np.percentile(y[seen], 5)))
            hi = max(hi, float(np.percentile(y[seen], 95)))
        pad = 0.1 * (hi - lo) + 1e-300
        item.setYRange(lo - pad, hi + pad, padding=0)
    if fit is not None and fit.resolved:
        grid = np.geomspace(fit.span[0], fit.span[1], 100)
        dashed = pg.mkPen("#000000", width=1.5, style=QtCore.Qt.PenStyle.DashLine)
        item.plot(grid, fit.at(grid), pen=dashed)


class DiagnosisView(QtWidgets.QWidget):
    """Verdict, evidence, ranking, screen, recommendation; the recalibration's error history."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.verdict = QtWidgets.QLabel("no diagnosis yet: load a run and a model, then Diagnose")
        self.verdict.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.verdict.setWordWrap(True)
        self.evidence = QtWidgets.QListWidget()
        self.evidence.setWordWrap(True)
        self.ranking = QtWidgets.QTableWidget(0, len(_RANK_COLUMNS))
        self.ranking.setHorizontalHeaderLabels(list(_RANK_COLUMNS))
        self.ranking.verticalHeader().hide()
        self.ranking.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.ranking.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.SingleSelection)
        header = self.ranking.horizontalHeader()
        header.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        self.screen_table = QtWidgets.QTableWidget(0, 3)
        self.screen_table.setHorizontalHeaderLabels(["ΔBIC (screen)", "candidate", "estimate"])
        self.screen_table.verticalHeader().hide()
        sh = self.screen_table.horizontalHeader()
        sh.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        sh.setStretchLastSection(True)
        # the read-out's plots would otherwise leave the screen table a row in a short window
        self.screen_table.setMinimumHeight(130)
        self.recommendation = QtWidgets.QLabel("")
        self.recommendation.setWordWrap(True)
        self.separation = QtWidgets.QLabel("")
        self.separation.setWordWrap(True)
        self.separation.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.separation.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self._make_readout()
        self.error = make_plot(
            "recalibration: error by iteration",
            "iteration",
            "LM cost [-]",
            log_y=True,
            legend=False,
        )
        self.error.getPlotItem().getAxis("left").setWidth(72)  # the label changes; ticks do not
        self.augment_summary = QtWidgets.QLabel("")
        self.augment_summary.setWordWrap(True)
        self.augment_summary.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self._lay_out()
        self.diagnosis = None
        self._costs: list[tuple[int, float]] = []

    def _lay_out(self) -> None:
        """The verdict, its read-out, the evidence and the ranking on the left; the screen, the
        read-out's plots and the recalibration on the right."""
        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.verdict)
        left.addWidget(self.separation)  # the tie's answer beside the verdict it settles
        left.addWidget(self.readout_text)  # what the unexplained misfit looks like
        left.addWidget(heading("Evidence in the data"))
        left.addWidget(self.evidence, 3)
        left.addWidget(heading("Verified candidates (everything recalibrated), best first"))
        left.addWidget(self.ranking, 2)
        left.addWidget(self.recommendation)
        right = QtWidgets.QVBoxLayout()
        right.addWidget(heading("Screen (harmonic-domain force estimate), best first"))
        right.addWidget(self.screen_table, 2)
        right.addWidget(self.readout_plots, 3)
        right.addWidget(self.error, 3)
        right.addWidget(self.augment_summary)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(left, 3)
        layout.addLayout(right, 2)

    def _make_readout(self) -> None:
        """The read-out's words and its two describing-function plots, hidden until a
        diagnosis has one."""
        self.readout_text = QtWidgets.QLabel("")
        self.readout_text.setWordWrap(True)
        self.readout_text.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.readout_text.setTextInteractionFlags(
            QtCore.Qt.TextInteractionFlag.TextSelectableByMouse
        )
        self.stiffness = make_plot(
            "stiffness", "amplitude A [m]", "k_eq [N/m]", log_x=True, legend=False
        )
        self.damping = make_plot(
            "damping", "amplitude A [m]", "c_eq [N s/m]", log_x=True, legend=False
        )
        for plot in (self.stiffness, self.damping):
            # wide enough for six-digit ticks from the start: the axis widens to its ticks only
            # on a later layout pass, and a window drawn before it shows the label over them
            plot.getPlotItem().getAxis("left").setWidth(76)
        self.readout_legend = QtWidgets.QLabel("")
        self.readout_legend.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.readout_legend.setWordWrap(True)
        plots = QtWidgets.QHBoxLayout()
        plots.addWidget(self.stiffness)
        plots.addWidget(self.damping)
        self.readout_plots = QtWidgets.QWidget()
        box = QtWidgets.QVBoxLayout(self.readout_plots)
        box.setContentsMargins(0, 0, 0, 0)
        box.addLayout(plots, 1)
        box.addWidget(self.readout_legend)
        self.readout_text.hide()
        self.readout_plots.hide()

    # -- the diagnosis ---------------------------------------------------------------------
    def show_diagnosis(self, d) -> None:
        """Show an :class:`analysis.diagnosis.Diagnosis`."""
        self.diagnosis = d
        colour, sentence = _VERDICTS.get(d.verdict, (WARN, d.verdict))
        cmp = d.comparison
        text = f"{status_chip(d.verdict.upper(), colour)} &nbsp; {sentence}"
        if d.verdict == "explained" and d.group:
            g = d.group
            names = "; ".join(r.candidate.label for r in g)
            tie = f" (tied within {d.settings.tie_bic:g} BIC: {names})" if len(g) > 1 else ""
            text += f": <b>{g[0].candidate.label}</b>{tie}"
            for r in g:
                if r.candidate.location.moves_as:
                    text += "<br>" + html.escape(_same_to_the_structure(r.candidate.location))
        text += (
            f"<br>model against the file: residual {cmp.rms_over_noise:.3g} x noise "
            f"(chi2/dof {cmp.chi2_per_dof:.3g}); {d.timings.get('total_s', math.nan):.1f} s"
        )
        self.verdict.setText(text)
        self.evidence.clear()
        for f in d.evidence.findings:
            mark = "■" if f.significant else "□"
            item = QtWidgets.QListWidgetItem(f"{mark} {f.text}")
            if f.significant:
                item.setForeground(QtGui.QBrush(QtGui.QColor(ALARM)))
                font = item.font()
                font.setBold(True)
                item.setFont(font)
            if f.points_at:
                item.setToolTip("points at: " + ", ".join(f.points_at))
            self.evidence.addItem(item)
        self._show_ranking(d)
        self._show_screen(d)
        self._show_readout(d)
        rec = d.recommendation
        self.recommendation.setText(
            f"To separate the tied candidates: {rec['text']}" if rec else ""
        )
        self._separation_text("", "")

    # -- the separating test ---------------------------------------------------------------
    def show_separation_note(self, text: str, plan=None) -> None:
        """A word on the separating test (under way, or why it cannot run here) and the plan
        file written for it."""
        lines = [text] if plan is None else [text, f"plan: {plan}"]
        self._separation_text("<br>".join(html.escape(line) for line in lines), "")

    def show_separation(self, sep, path) -> None:
        """Show an :class:`analysis.diagnosis.separate.Separation`: which candidate the
        separating run puts first alone, or which remain tied."""
        if sep.resolved:
            head = (
                f"{status_chip('RESOLVED', OK)} &nbsp; the separating run puts "
                f"<b>{html.escape(sep.tied[0])}</b> first alone"
            )
        else:
            head = (
                f"{status_chip('STILL TIED', WARN)} &nbsp; within {sep.tie_chi2:g} on the "
                f"separating run: <b>{html.escape('; '.join(sep.tied))}</b>"
            )
        rows = "<br>".join(
            f"{html.escape(r['label'])}: residual {r['rms_over_noise']:.3g} x noise, "
            f"Δχ² {r['delta_chi2']:.1f}"
            for r in sep.ranking
        )
        name = html.escape(Path(path).name)
        self._separation_text(f"{head}<br>separating run {name}:<br>{rows}", str(path))

    def _separation_text(self, text: str, tip: str) -> None:
        self.separation.setText(text)
        self.separation.setToolTip(tip)

    # -- the missing law ------------------------------------------------------------------
    def _show_readout(self, d) -> None:
        """The read-out of an unexplained misfit (:class:`analysis.diagnosis.ForceReadout`):
        its words under the verdict and its describing function against the amplitude;
        nothing of a previous one stays when a diagnosis has none."""
        ro = d.readout
        for plot in (self.stiffness, self.damping):
            plot.getPlotItem().clear()
        if ro is None:
            self.readout_text.setText("")
            self.readout_legend.setText("")
            self.readout_text.hide()
            self.readout_plots.hide()
            return
        text = f"<b>What the data show about the missing law:</b> {html.escape(ro.text)}"
        place = next(
            (
                f.candidate.location
                for f in [*d.ranking, *d.screen]
                if f.candidate.location.name == ro.location
            ),
            None,
        )
        if place is not None and place.moves_as:
            text += "<br>" + html.escape(_same_to_the_structure(place))
        self.readout_text.setText(text)
        u = ro.units
        r = ro.reading
        for plot, name, unit in ((self.stiffness, "k_eq", u["k"]), (self.damping, "c_eq", u["c"])):
            _label(plot, "bottom", f"amplitude A [{u['x']}]")
            _label(plot, "left", f"{name} [{unit}]")
        _draw_describing_function(
            self.stiffness,
            ro,
            ro.k_eq,
            ro.sigma_k,
            None if r is None else r.k_bins,
            None if r is None else r.stiffness,
        )
        _draw_describing_function(
            self.damping,
            ro,
            ro.c_eq,
            ro.sigma_c,
            None if r is None else r.c_bins,
            None if r is None else (r.damping if r.damping.changes else r.damping_whole),
        )
        levels = sorted(set(ro.level_n[np.asarray(ro.seen, bool)].tolist()))
        keys = [(f"{lv:g} N", color(i)) for i, lv in enumerate(levels)]
        self.readout_legend.setText(
            f"equivalent stiffness and damping at {html.escape(ro.read_at)}, per step by force "
            "level: "
            + legend_html([*keys, ("binned", "#000000")])
            + "; bars: one standard error; dashed: the fit where its slope is resolved"
        )
        self.readout_text.show()
        self.readout_plots.show()

    def _show_ranking(self, d) -> None:
        self.ranking.setRowCount(len(d.ranking))
        for r, rc in enumerate(d.ranking):
            place = rc.candidate.location
            alike = f" (moves as {', '.join(place.moves_as)})" if place.moves_as else ""
            cells = [
                str(rc.rank),
                str(rc.group),
                rc.candidate.label + alike,
                f"{rc.rms_over_noise:.3g}",
                f"{rc.delta_bic:.1f}",
                _parameters(rc.verified.parameters),
            ]
            for k, text in enumerate(cells):
                item = no_edit(QtWidgets.QTableWidgetItem(text))
                tip = text
                if k == 2 and place.moves_as:
                    tip = f"{rc.candidate.label}\n{_same_to_the_structure(place)}"
                item.setToolTip(tip)
                if rc.group == 1 and d.verdict == "explained":
                    item.setBackground(QtGui.QBrush(QtGui.QColor("#e3f4e8")))
                self.ranking.setItem(r, k, item)
        if d.ranking:
            self.ranking.selectRow(0)

    def _show_screen(self, d) -> None:
        fits = d.screen[:12]
        base = d.baseline.bic if d.baseline is not None else 0.0
        self.screen_table.setRowCount(len(fits))
        for r, f in enumerate(fits):
            cells = [f"{f.bic - base:.1f}", f.candidate.label, _parameters(f.values)]
            for k, text in enumerate(cells):
                self.screen_table.setItem(r, k, no_edit(QtWidgets.QTableWidgetItem(text)))

    def selected(self):
        """The :class:`~analysis.diagnosis.RankedCandidate` selected (the best by default)."""
        d = self.diagnosis
        if d is None or not d.ranking:
            return None
        rows = self.ranking.selectionModel().selectedRows()
        return d.ranking[rows[0].row()] if rows else d.ranking[0]

    # -- the recalibration -----------------------------------------------------------------
    def augment_started(self, label: str, before_rms: float) -> None:
        self._costs = []
        self.error.getPlotItem().clear()
        self.error.getPlotItem().setLabel("left", "LM cost [-]")
        self.augment_summary.setText(
            f"adding <b>{label}</b> and recalibrating everything… (residual before: "
            f"{before_rms:.3g} x noise)"
        )

    def augment_progress(self, event: Event) -> None:
        """An event of :func:`analysis.diagnosis.augment`: its iterations draw the cost."""
        if not isinstance(event, Iteration):
            return
        self._costs.append((event.iteration, event.cost))
        it = np.array([i for i, _ in self._costs], dtype=float)
        cost = np.array([c for _, c in self._costs])
        item = self.error.getPlotItem()
        item.clear()
        item.plot(
            it,
            np.maximum(cost, 1e-12),
            pen=pg.mkPen(PALETTE[1], width=2.5),
            symbol="o",
            symbolSize=7,
            symbolBrush=PALETTE[1],
        )
        item.setTitle("recalibration: " + legend_html([("LM cost (weighted misfit)", PALETTE[1])]))

    def augment_finished(self, result) -> None:
        """Show an :class:`analysis.diagnosis.AugmentResult`."""
        levels = ", ".join(f"{lv:g} N {v:.3g}" for lv, v in result.level_rms("after").items())
        self.augment_summary.setText(
            f"added <b>{result.candidate.label}</b>: residual "
            f"<b>{result.before.rms_over_noise:.3g} → {result.after.rms_over_noise:.3g}</b> x "
            f"noise ({result.residual_drop:.3g}-fold drop); per level after: {levels}<br>"
            f"parameters: {_parameters(result.parameters)}"
        )
        hist = [h for h in result.history if h.get("stage") in ("lm", "reweighted")]
        if hist:
            it = np.array([h["iteration"] for h in hist], dtype=float)
            chi2 = np.array([h["chi2_per_dof"] for h in hist])
            item = self.error.getPlotItem()
            item.clear()
            item.setLabel("left", "chi²/dof [-]")
            item.plot(
                it,
                chi2,
                pen=pg.mkPen(PALETTE[1], width=2.5),
                symbol="o",
                symbolSize=7,
                symbolBrush=PALETTE[1],
            )
            before = result.before.chi2_per_dof
            if math.isfinite(before) and before > 0:
                item.plot(
                    [it.min(), it.max()],
                    [before, before],
                    pen=pg.mkPen(ALARM, width=2, style=QtCore.Qt.PenStyle.DashLine),
                )
            item.addLine(y=0.0, pen=pg.mkPen(OK, width=1.5, style=QtCore.Qt.PenStyle.DotLine))
            item.setTitle(
                legend_html(
                    [("with the effect", PALETTE[1]), ("without it", ALARM), ("the noise", OK)]
                )
            )
