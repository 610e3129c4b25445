"""What a diagnosis tries: its settings, the candidates, the recalibration's starts.

The settings are a form generated from :class:`analysis.diagnosis.DiagnosisSettings` (the GUI
runs verifications in its own process: ``workers = 1`` unless changed); the candidates are
:func:`analysis.diagnosis.default_candidates` of the model, optionally kept to some locations
(``point 5``, ``mounts``, ``joint clamp rz``) and laws (``quadratic_damper``).
"""

from __future__ import annotations

import dataclasses

from PySide6 import QtWidgets

from analysis.diagnosis import DiagnosisSettings, default_candidates
from rig.gui.forms import SettingsForm
from rig.gui.settings_fields import dataclass_fields

__all__ = ["GUI_DIAGNOSIS", "DiagnosisOptions"]

#: The GUI's diagnosis defaults: verifications in this process (no process pool forked from a
#: GUI), otherwise the library's defaults.
GUI_DIAGNOSIS = DiagnosisSettings(workers=1)


def _names(text: str) -> list[str]:
    return [t.strip() for t in text.replace(";", ",").split(",") if t.strip()]


class DiagnosisOptions(QtWidgets.QWidget):
    """Candidate filters, recalibration starts and the diagnosis settings."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.locations = QtWidgets.QLineEdit()
        self.locations.setPlaceholderText("all (e.g. point 5, point 7, mounts)")
        self.laws = QtWidgets.QLineEdit()
        self.laws.setPlaceholderText("all (e.g. quadratic_damper, cubic_spring)")
        self.starts = QtWidgets.QSpinBox()
        self.starts.setRange(0, 200)
        self.starts.setValue(8)
        self.starts.setToolTip("Latin hypercube starts of the recalibration (besides the screen's)")
        self.form = SettingsForm(
            [("Diagnosis settings", dataclass_fields(DiagnosisSettings, "diagnosis"))]
        )
        self.form.set_document({"diagnosis": dataclasses.asdict(GUI_DIAGNOSIS)})
        filters = QtWidgets.QGroupBox("Candidates")
        rows = QtWidgets.QFormLayout(filters)
        rows.addRow("locations", self.locations)
        rows.addRow("laws", self.laws)
        rows.addRow("recalibration starts", self.starts)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(filters)
        layout.addWidget(self.form)

    def settings(self) -> DiagnosisSettings:
        """The settings in the form (raises ValueError with the settings' own message, which
        is also shown above the form)."""
        self.form.clear_errors()
        values = self.form.document().get("diagnosis", {})
        try:
            return DiagnosisSettings(**values)
        except (TypeError, ValueError) as exc:
            self.form.show_error("", str(exc))
            raise ValueError(str(exc)) from None

    def candidates(self, model):
        """The candidates of ``model`` the filters keep (None: all of them)."""
        locations, laws = _names(self.locations.text()), _names(self.laws.text())
        if not locations and not laws:
            return None
        return [
            c
            for c in default_candidates(model)
            if (not locations or c.location.name in locations) and (not laws or c.law.kind in laws)
        ]
