"""What a diagnosis tries: its settings, the candidates, the recalibration's starts.

The settings are a form generated from :class:`analysis.diagnosis.DiagnosisSettings` (the GUI
runs verifications in its own process: ``workers = 1`` unless changed); the candidates are
:func:`analysis.diagnosis.default_candidates` of the model, optionally kept to some locations
(``point 5``, ``springs k_mount``, ``joint clamp rz``) and laws (``quadratic_damper``).

A first diagnosis needs none of the expert settings: the candidate filters, the recalibration's
starts and the time budget are shown; the rest (:data:`ADVANCED`) wait closed under
*Advanced*, each with what it does and its default in its tooltip.
"""

from __future__ import annotations

import dataclasses

from PySide6 import QtWidgets

from analysis.diagnosis import DiagnosisSettings, default_candidates
from analysis.settings import ConfigError, build
from rig.gui.forms import SettingsForm
from rig.gui.settings_fields import Field, dataclass_fields, format_value

__all__ = ["ADVANCED", "BASIC", "GUI_DIAGNOSIS", "DiagnosisOptions"]

#: The GUI's diagnosis defaults: verifications in this process (no process pool forked from a
#: GUI), otherwise the library's defaults.
GUI_DIAGNOSIS = DiagnosisSettings(workers=1)

#: Diagnosis settings a first-time user sees; every other one is under *Advanced*.
BASIC = ("budget_evaluations",)
#: The expert settings, closed under *Advanced* until opened.
ADVANCED = tuple(f.name for f in dataclasses.fields(DiagnosisSettings) if f.name not in BASIC)

_WHY_DEFAULT = {
    "workers": "1 here: the GUI verifies in its own process (the library's default, "
    f"{DiagnosisSettings().workers}, forks worker processes)",
}


def _with_default(field: Field) -> Field:
    """The field with its default (and why it is that) in its tooltip."""
    name = field.name
    default = _WHY_DEFAULT.get(name, format_value(getattr(GUI_DIAGNOSIS, name)))
    text = f"{field.tooltip}\n\nDefault: {default}" if field.tooltip else f"Default: {default}"
    return dataclasses.replace(field, tooltip=text)


def _names(text: str) -> list[str]:
    return [t.strip() for t in text.replace(";", ",").split(",") if t.strip()]


class DiagnosisOptions(QtWidgets.QWidget):
    """Candidate filters, recalibration starts and the diagnosis settings."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.locations = QtWidgets.QLineEdit()
        self.locations.setPlaceholderText("all (e.g. point 5, point 7 x, springs k_mount)")
        self.laws = QtWidgets.QLineEdit()
        self.laws.setPlaceholderText("all (e.g. quadratic_damper, cubic_spring)")
        self.starts = QtWidgets.QSpinBox()
        self.starts.setRange(0, 200)
        self.starts.setValue(8)
        self.starts.setToolTip(
            "Latin hypercube starts of the recalibration (besides the screen's)\n\nDefault: 8"
        )
        fields = [_with_default(f) for f in dataclass_fields(DiagnosisSettings, "diagnosis")]
        self.form = SettingsForm(
            [
                ("Diagnosis settings", [f for f in fields if f.name in BASIC]),
                ("Advanced", [f for f in fields if f.name in ADVANCED]),
            ],
            collapsed=("Advanced",),
        )
        self.advanced = self.form.collapsible["Advanced"]
        self.advanced.toggle.setText(f"Advanced ({len(ADVANCED)} expert settings)")
        self.advanced.toggle.setToolTip(
            "settings of the screen, the verifications and the verdict; the defaults suit a "
            "first diagnosis (each entry's tooltip says what it does and its default)"
        )
        self.restore = QtWidgets.QPushButton("Restore defaults")
        self.restore.setToolTip("every diagnosis setting back to its default")
        self.restore.clicked.connect(self.restore_defaults)
        self.advanced.body.layout().addRow(self.restore)
        self.restore_defaults()
        filters = QtWidgets.QGroupBox("Candidates")
        rows = QtWidgets.QFormLayout(filters)
        rows.addRow("locations", self.locations)
        rows.addRow("laws", self.laws)
        rows.addRow("recalibration starts", self.starts)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(filters)
        layout.addWidget(self.form)

    def restore_defaults(self) -> None:
        """Every diagnosis setting back to the GUI's default (:data:`GUI_DIAGNOSIS`)."""
        self.form.set_document({"diagnosis": dataclasses.asdict(GUI_DIAGNOSIS)})

    def settings(self) -> DiagnosisSettings:
        """The settings in the form (raises ValueError with the settings' own message, which
        is also shown at the entry it names, opening *Advanced* when it is there, or above
        the form)."""
        self.form.clear_errors()
        values = self.form.document().get("diagnosis", {})
        try:
            return build(DiagnosisSettings, values, "diagnosis settings", at=("diagnosis",))
        except ConfigError as exc:
            self.form.show_error(exc.path, exc.problem)
            raise ValueError(str(exc)) from None

    def candidates(self, model):
        """The candidates of ``model`` the filters keep (None: all of them)."""
        locations, laws = _names(self.locations.text()), _names(self.laws.text())
        if not locations and not laws:
            return None
        return [
            c
            for c in default_candidates(model, scope="structure")
            if (not locations or c.location.name in locations) and (not laws or c.law.kind in laws)
        ]
