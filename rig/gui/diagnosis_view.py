"""A diagnosis in the workbench: the verdict, the evidence, the ranked candidates, and the
error falling while the chosen effect is added and everything recalibrated.

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
    OK,
    PALETTE,
    WARN,
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
        self.recommendation = QtWidgets.QLabel("")
        self.recommendation.setWordWrap(True)
        self.separation = QtWidgets.QLabel("")
        self.separation.setWordWrap(True)
        self.separation.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.separation.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
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

        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.verdict)
        left.addWidget(self.separation)  # the tie's answer beside the verdict it settles
        left.addWidget(heading("Evidence in the data"))
        left.addWidget(self.evidence, 3)
        left.addWidget(heading("Verified candidates (everything recalibrated), best first"))
        left.addWidget(self.ranking, 2)
        left.addWidget(self.recommendation)
        right = QtWidgets.QVBoxLayout()
        right.addWidget(heading("Screen (harmonic-domain force estimate), best first"))
        right.addWidget(self.screen_table, 2)
        right.addWidget(self.error, 3)
        right.addWidget(self.augment_summary)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(left, 3)
        layout.addLayout(right, 2)
        self.diagnosis = None
        self._costs: list[tuple[int, float]] = []

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

    def _show_ranking(self, d) -> None:
        self.ranking.setRowCount(len(d.ranking))
        for r, rc in enumerate(d.ranking):
            cells = [
                str(rc.rank),
                str(rc.group),
                rc.candidate.label,
                f"{rc.rms_over_noise:.3g}",
                f"{rc.delta_bic:.1f}",
                _parameters(rc.verified.parameters),
            ]
            for k, text in enumerate(cells):
                item = no_edit(QtWidgets.QTableWidgetItem(text))
                item.setToolTip(text)
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
