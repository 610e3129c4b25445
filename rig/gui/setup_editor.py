"""The lab-setup editor: DAQ, drive, amplifier and every channel with its sensitivity.

Sections are generated from :mod:`rig.config.setup`'s dataclasses; the setup is built with
:func:`rig.config.setup.setup_from_dict`, the reader of setup files.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rig.config.setup import (
    AmplifierSetup,
    ChannelSetup,
    DaqSetup,
    DriveSetup,
    LabSetup,
    builtin_setups,
    load_setup,
    setup_from_dict,
)
from rig.gui.forms import RowsTable, SettingsForm
from rig.gui.settings_editor import SettingsEditor
from rig.gui.settings_fields import dataclass_fields

__all__ = ["SetupEditor"]


def setup_form() -> SettingsForm:
    """The form of a lab setup."""
    general = dataclass_fields(LabSetup)
    form = SettingsForm(
        [
            ("Setup", general),
            ("DAQ", dataclass_fields(DaqSetup, "daq")),
            ("Drive", dataclass_fields(DriveSetup, "drive")),
            ("Amplifier", dataclass_fields(AmplifierSetup, "amplifier")),
            ("Channels", []),
        ]
    )
    columns = RowsTable(dataclass_fields(ChannelSetup))
    form.add_rows("Channels", "channels", "channels, in acquisition order", columns)
    return form


class SetupEditor(SettingsEditor):
    """Choose, open, edit, check and save a lab setup."""

    source = "setup form"
    what = "setup"

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.add_form("setup", setup_form())

    def builtins(self) -> Mapping[str, Path]:
        return builtin_setups()

    def read(self, name_or_path: str) -> LabSetup:
        return load_setup(name_or_path)

    def build(self, doc: dict[str, Any]) -> LabSetup:
        return setup_from_dict(doc, self.source)

    def describe(self, value: LabSetup) -> str:
        n = len(value.channels)
        return (
            f"{n} channels, {value.daq.device} at {value.daq.sample_rate_hz:g} Hz, drive at "
            f"point {value.drive.point} {value.drive.direction} (limit {value.drive.limit_v:g} V)"
        )
