"""An editor of one settings file (a lab setup or a plan): choose, open, edit, check, save.

:class:`SettingsEditor` holds a combo of the built-in files, Open and Save buttons and a
:class:`~rig.gui.forms.SettingsForm`. :meth:`SettingsEditor.check` builds the settings object
from the form's document with the loader the command line uses and shows its error, if any,
next to the field it names. Subclasses say which files, which loader and which fields.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomli_w
from PySide6 import QtCore, QtWidgets

from rig.config.tomlconfig import ConfigError
from rig.gui.forms import SettingsForm

__all__ = ["SettingsEditor"]

logger = logging.getLogger(__name__)


class SettingsEditor(QtWidgets.QWidget):
    """Base of the setup and plan editors.

    Signals
    -------
    edited
        The form changed (the panel re-checks after a short delay).
    loaded(object)
        A settings object was loaded from a built-in name or a file.
    """

    edited = QtCore.Signal()
    loaded = QtCore.Signal(object)

    #: Name of the form as the loader's messages give it ("plan form: excitation...").
    source = "form"
    what = "settings"

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.choice = QtWidgets.QComboBox()
        self.choice.setToolTip(f"built-in {self.what}s, or a file opened")
        self.open_button = QtWidgets.QPushButton("Open…")
        self.save_button = QtWidgets.QPushButton("Save as…")
        self.origin = QtWidgets.QLabel("")
        self.origin.setWordWrap(True)
        self.origin.setStyleSheet("color: #555555;")
        self.summary = QtWidgets.QLabel("")
        self.summary.setWordWrap(True)
        self.summary.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.stack = QtWidgets.QStackedWidget()
        self.forms: dict[str, SettingsForm] = {}
        scroll = QtWidgets.QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.stack)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel(f"{self.what.capitalize()}:"))
        top.addWidget(self.choice, 1)
        top.addWidget(self.open_button)
        top.addWidget(self.save_button)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(top)
        layout.addWidget(self.origin)
        layout.addWidget(self.summary)
        layout.addWidget(scroll, 1)
        self.kind = ""
        self.value: Any = None
        self.path: Path | None = None
        for name in sorted(self.builtins()):
            self.choice.addItem(name, name)
        self.choice.activated.connect(lambda _i: self.load(self.choice.currentData()))
        self.open_button.clicked.connect(self._open_dialog)
        self.save_button.clicked.connect(self._save_dialog)

    # -- for subclasses ----------------------------------------------------------------------
    def builtins(self) -> Mapping[str, Path]:
        raise NotImplementedError

    def read(self, name_or_path: str) -> Any:
        """Load a built-in by name or a file (raises ConfigError)."""
        raise NotImplementedError

    def build(self, doc: dict[str, Any]) -> Any:
        """The settings object of a document (raises ConfigError naming ``self.source``)."""
        raise NotImplementedError

    def kind_of(self, value: Any) -> str:
        """Which of :attr:`forms` edits ``value``."""
        return next(iter(self.forms))

    def describe(self, value: Any) -> str:
        return ""

    # -- forms -----------------------------------------------------------------------------
    def add_form(self, kind: str, form: SettingsForm) -> None:
        self.forms[kind] = form
        self.stack.addWidget(form)
        form.changed.connect(self.edited.emit)
        if not self.kind:
            self.kind = kind

    @property
    def form(self) -> SettingsForm:
        """The form in use."""
        return self.forms[self.kind]

    def document(self) -> dict[str, Any]:
        return self.form.document()

    def set_value(self, value: Any, origin: str) -> None:
        """Show a settings object in the form."""
        self.kind = self.kind_of(value)
        self.stack.setCurrentWidget(self.form)
        self.form.set_document(value.to_dict())
        self.value = value
        self.origin.setText(origin)
        self.summary.setText(self.describe(value))

    def load(self, name_or_path: str) -> bool:
        """Load a built-in or a file into the form; an error is shown above the form."""
        try:
            value = self.read(name_or_path)
        except ConfigError as exc:
            self.form.clear_errors()
            self.form.show_error("", str(exc))
            return False
        builtin = name_or_path in self.builtins()
        self.path = None if builtin else Path(name_or_path)
        if builtin:
            self.choice.setCurrentIndex(self.choice.findData(name_or_path))
            origin = f"built-in {self.what} {name_or_path!r}"
        else:
            label = f"file {Path(name_or_path).name}"
            if self.choice.findData(str(name_or_path)) < 0:
                self.choice.addItem(label, str(name_or_path))
            self.choice.setCurrentIndex(self.choice.findData(str(name_or_path)))
            origin = f"file {name_or_path}"
        self.set_value(value, origin)
        self.loaded.emit(value)
        return True

    def check(self) -> tuple[Any, str]:
        """Build the settings from the form; on an error show it at its field.

        Returns
        -------
        (object or None, str)
            The settings (None if invalid) and the error message ("" if valid).
        """
        form = self.form
        form.clear_errors()
        try:
            value = self.build(self.document())
        except ConfigError as exc:
            form.show_error(exc.path, exc.problem)
            self.summary.setText("")
            return None, str(exc)
        self.value = value
        self.summary.setText(self.describe(value))
        return value, ""

    def save(self, path: str | Path) -> Path:
        """Write the form's settings (checked) to a TOML file the loader reads back."""
        value, error = self.check()
        if value is None:
            raise ConfigError(error)
        path = Path(path)
        header = (
            f"# {self.what.capitalize()} {getattr(value, 'name', '')!r}, saved from the lab GUI\n\n"
        )
        path.write_text(header + tomli_w.dumps(value.to_dict()), encoding="utf-8")
        self.path = path
        self.origin.setText(f"file {path}")
        return path

    # -- dialogs ---------------------------------------------------------------------------
    def _open_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, f"Open a {self.what}", "", "TOML files (*.toml);;All files (*)"
        )
        if name:
            self.load(name)

    def _save_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getSaveFileName(
            self, f"Save the {self.what}", "", "TOML files (*.toml)"
        )
        if not name:
            return
        try:
            self.save(name)
        except (ConfigError, OSError) as exc:
            QtWidgets.QMessageBox.warning(self, f"Save the {self.what}", str(exc))
