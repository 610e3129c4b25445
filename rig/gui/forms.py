"""Settings forms generated from the frozen settings dataclasses, validated by the settings.

:class:`SettingsForm` shows the fields of :mod:`rig.gui.settings_fields` in sections, each
entry with its error message right below it; :class:`RowsTable` edits an array of tables
(frequency ranges, response limits, channels). Validation is the settings' own: the editor
hands :meth:`SettingsForm.document` to the loader, and a
:class:`~rig.config.tomlconfig.ConfigError` (``"plan form: excitation.levels_n[1]: must be > 0"``)
is
shown next to the entry its key path names (:meth:`SettingsForm.show_error`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from rig.config.tomlconfig import KeyPath, dotted
from rig.gui.settings_fields import (
    Field,
    format_value,
    get_key,
    parse_value,
    put_key,
)
from rig.gui.style import ALARM

__all__ = ["CollapsibleSection", "RowsTable", "SettingsForm"]


# ------------------------------------------------------------------------ widgets


def _error_label() -> QtWidgets.QLabel:
    label = QtWidgets.QLabel()
    label.setWordWrap(True)
    label.setStyleSheet(f"color: {ALARM};")
    label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
    label.hide()
    return label


def _stacked(widget: QtWidgets.QWidget, error: QtWidgets.QLabel) -> QtWidgets.QWidget:
    """An entry with its error message right below it."""
    box = QtWidgets.QWidget()
    column = QtWidgets.QVBoxLayout(box)
    column.setContentsMargins(0, 0, 0, 0)
    column.setSpacing(1)
    column.addWidget(widget)
    column.addWidget(error)
    return box


class RowsTable(QtWidgets.QWidget):
    """An editable array of tables (``[[limits.response]]``, ``ranges``, ``[[channels]]``).

    Parameters
    ----------
    columns : list of Field
        One column per field (``key`` is the field's name inside a row).
    """

    changed = QtCore.Signal()

    def __init__(self, columns: list[Field], parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.columns = list(columns)
        self.table = QtWidgets.QTableWidget(0, len(self.columns))
        self.table.setHorizontalHeaderLabels([c.label for c in self.columns])
        for i, c in enumerate(self.columns):
            item = self.table.horizontalHeaderItem(i)
            if item is not None and c.tooltip:
                item.setToolTip(c.tooltip)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        self.table.verticalHeader().setDefaultSectionSize(24)
        self.table.itemChanged.connect(lambda _item: self.changed.emit())
        add = QtWidgets.QPushButton("Add row")
        remove = QtWidgets.QPushButton("Remove row")
        add.clicked.connect(self.add_row)
        remove.clicked.connect(self.remove_row)
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(add)
        buttons.addWidget(remove)
        buttons.addStretch(1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.table)
        layout.addLayout(buttons)

    def add_row(self) -> None:
        self.table.insertRow(self.table.rowCount())
        self.changed.emit()

    def remove_row(self) -> None:
        row = self.table.currentRow()
        if row < 0:
            row = self.table.rowCount() - 1
        if row >= 0:
            self.table.removeRow(row)
            self.changed.emit()

    def rows(self) -> list[dict[str, Any]]:
        """The rows as tables of the document (empty cells left out)."""
        out = []
        for r in range(self.table.rowCount()):
            row: dict[str, Any] = {}
            for c, col in enumerate(self.columns):
                item = self.table.item(r, c)
                value = parse_value(col.kind, item.text() if item else "")
                if value is None or (value == "" and col.optional):
                    continue
                row[col.name] = value
            out.append(row)
        return out

    def set_rows(self, rows: Iterable[Mapping[str, Any]]) -> None:
        rows = list(rows)
        blocker = QtCore.QSignalBlocker(self.table)
        self.table.setRowCount(len(rows))
        for r, row in enumerate(rows):
            for c, col in enumerate(self.columns):
                value = row.get(col.name)
                if col.name == "point" and isinstance(value, int) and value < 0:
                    value = None  # "no point" (the limit names a channel)
                self.table.setItem(r, c, QtWidgets.QTableWidgetItem(format_value(value)))
        del blocker
        self.table.resizeColumnsToContents()
        self.changed.emit()

    def mark_row(self, row: int | None) -> None:
        """Highlight a row (None: none)."""
        for r in range(self.table.rowCount()):
            for c in range(self.table.columnCount()):
                item = self.table.item(r, c)
                if item is None:
                    item = QtWidgets.QTableWidgetItem("")
                    blocker = QtCore.QSignalBlocker(self.table)
                    self.table.setItem(r, c, item)
                    del blocker
                brush = QtGui.QBrush(QtGui.QColor("#f8d7da")) if r == row else QtGui.QBrush()
                item.setBackground(brush)


class CollapsibleSection(QtWidgets.QWidget):
    """A titled section whose body opens and closes under an arrow button (closed at first).

    Parameters
    ----------
    title : str
        The button's text (``"Advanced"``).
    body : QWidget
        What the section shows when open.
    """

    def __init__(
        self, title: str, body: QtWidgets.QWidget, parent: QtWidgets.QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.body = body
        self.toggle = QtWidgets.QToolButton()
        self.toggle.setText(title)
        self.toggle.setCheckable(True)
        self.toggle.setChecked(False)
        self.toggle.setToolButtonStyle(QtCore.Qt.ToolButtonStyle.ToolButtonTextBesideIcon)
        self.toggle.setArrowType(QtCore.Qt.ArrowType.RightArrow)
        self.toggle.setAutoRaise(True)
        font = self.toggle.font()
        font.setBold(True)
        self.toggle.setFont(font)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addWidget(self.toggle)
        layout.addWidget(body)
        body.setVisible(False)
        self.toggle.toggled.connect(self._toggled)

    def _toggled(self, open_: bool) -> None:
        self.toggle.setArrowType(
            QtCore.Qt.ArrowType.DownArrow if open_ else QtCore.Qt.ArrowType.RightArrow
        )
        self.body.setVisible(open_)

    @property
    def expanded(self) -> bool:
        return self.toggle.isChecked()

    def set_expanded(self, open_: bool = True) -> None:
        self.toggle.setChecked(open_)


@dataclass
class _Entry:
    field: Field | None
    widget: QtWidgets.QWidget
    error: QtWidgets.QLabel
    get: Callable[[], Any]
    set: Callable[[Any], None]
    rows: RowsTable | None = None
    section: str = ""


class SettingsForm(QtWidgets.QWidget):
    """A form over a settings document, in sections.

    Parameters
    ----------
    sections : list of (title, list of Field)
        Each section is a group box of labelled entries; an entry's error message appears
        right below it.
    collapsed : iterable of str
        Titles of sections shown closed under an arrow button (:class:`CollapsibleSection`)
        until the operator opens them, or an error in one of their entries is shown.

    Signals
    -------
    changed
        Any entry was edited.
    """

    changed = QtCore.Signal()

    def __init__(
        self,
        sections: list[tuple[str, list[Field]]],
        parent: QtWidgets.QWidget | None = None,
        *,
        collapsed: Iterable[str] = (),
    ) -> None:
        super().__init__(parent)
        self._entries: dict[str, _Entry] = {}
        self._layouts: dict[str, QtWidgets.QFormLayout] = {}
        self.collapsible: dict[str, CollapsibleSection] = {}
        self.general_error = _error_label()
        closed = set(collapsed)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.general_error)
        for title, fields in sections:
            box = QtWidgets.QGroupBox("" if title in closed else title)
            form = QtWidgets.QFormLayout(box)
            form.setFieldGrowthPolicy(QtWidgets.QFormLayout.FieldGrowthPolicy.ExpandingFieldsGrow)
            self._layouts[title] = form
            for f in fields:
                self._add_field(form, f, title)
            if title in closed:
                section = CollapsibleSection(title, box)
                self.collapsible[title] = section
                layout.addWidget(section)
            else:
                layout.addWidget(box)
        layout.addStretch(1)

    # -- building ---------------------------------------------------------------------------
    def _add_field(self, form: QtWidgets.QFormLayout, f: Field, section: str = "") -> None:
        if f.kind == "flag":
            box = QtWidgets.QCheckBox()
            box.toggled.connect(lambda _v: self.changed.emit())
            widget: QtWidgets.QWidget = box
            get, put = box.isChecked, (lambda v, b=box: b.setChecked(bool(v)))
        elif f.kind == "choice":
            combo = QtWidgets.QComboBox()
            combo.addItems(list(f.choices))
            combo.currentTextChanged.connect(lambda _t: self.changed.emit())
            widget = combo
            get = combo.currentText

            def put(v, c=combo):
                c.setCurrentText(format_value(v))

        else:
            line = QtWidgets.QLineEdit()
            line.textChanged.connect(lambda _t: self.changed.emit())
            widget = line
            get = lambda ln=line, k=f.kind: parse_value(k, ln.text())  # noqa: E731

            def put(v, ln=line):
                ln.setText(format_value(v))

        widget.setObjectName(f.key)
        widget.setToolTip(f.tooltip)
        label = QtWidgets.QLabel(f.label)
        label.setToolTip(f.tooltip)
        error = _error_label()
        form.addRow(label, _stacked(widget, error))
        self._entries[f.key] = _Entry(f, widget, error, get, put, section=section)

    def add_rows(self, section: str, key: str, label: str, table: RowsTable) -> None:
        """Add an array of tables (``key``) to a section."""
        form = self._layouts[section]
        error = _error_label()
        table.setObjectName(key)
        table.changed.connect(self.changed.emit)
        form.addRow(QtWidgets.QLabel(label))
        form.addRow(_stacked(table, error))
        self._entries[key] = _Entry(
            None, table, error, table.rows, table.set_rows, table, section=section
        )

    # -- values -----------------------------------------------------------------------------
    def widget(self, key: str) -> QtWidgets.QWidget:
        """The entry of a key (for tests and focus)."""
        return self._entries[key].widget

    def set_document(self, doc: Mapping[str, Any]) -> None:
        """Fill every entry from a settings document (missing keys leave entries empty)."""
        blocker = QtCore.QSignalBlocker(self)
        for key, entry in self._entries.items():
            value = get_key(doc, key)
            if value is None and entry.rows is not None:
                value = []
            entry.set(value)
        del blocker
        self.clear_errors()
        self.changed.emit()

    def document(self) -> dict[str, Any]:
        """The settings document the entries give (empty optional entries left out)."""
        doc: dict[str, Any] = {}
        for key, entry in self._entries.items():
            value = entry.get()
            if entry.field is not None and entry.field.optional and value in (None, ""):
                if entry.field.kind not in ("text", "choice") or value is None:
                    continue
            if value is None:
                continue
            put_key(doc, key, value)
        return doc

    # -- errors -----------------------------------------------------------------------------
    def clear_errors(self) -> None:
        self.general_error.hide()
        for entry in self._entries.values():
            entry.error.hide()
            entry.widget.setStyleSheet("")
            if entry.rows is not None:
                entry.rows.mark_row(None)

    def show_error(self, path: str | KeyPath, problem: str) -> str:
        """Show ``problem`` next to the entry the key path names (a tuple, or dotted text
        without indices); returns the key used ("" when no entry matches: the message then
        heads the form)."""
        if isinstance(path, str):
            path = tuple(path.split(".")) if path else ()
        parts = [p for p in path if isinstance(p, str)]
        rows = [p for p in path if isinstance(p, int)]
        row = rows[0] if rows else None
        for n in range(len(parts), 0, -1):
            key = ".".join(parts[:n])
            entry = self._entries.get(key)
            if entry is None:
                continue
            # from the entry's own name on: "levels_n[1]", "ranges[0].stop_hz"
            where = dotted(path[path.index(parts[n - 1]) :])
            entry.error.setText(f"{where}: {problem}")
            entry.error.show()
            if entry.section in self.collapsible:
                self.collapsible[entry.section].set_expanded(True)  # the error must be seen
            if entry.rows is not None:
                entry.rows.mark_row(row)
            else:
                entry.widget.setStyleSheet(f"border: 2px solid {ALARM};")
            return key
        self.general_error.setText(f"{dotted(path)}: {problem}" if path else problem)
        self.general_error.show()
        return ""

    def error_text(self, key: str) -> str:
        """The message shown at an entry ("" if none)."""
        entry = self._entries[key]
        return entry.error.text() if entry.error.isVisibleTo(self) else ""
