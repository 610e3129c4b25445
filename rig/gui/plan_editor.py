"""The plan editor: frequency ranges, levels, orders, acquisition, control, limits, pretest.

The form's sections, kinds, choices and tooltips are generated from the plan's declared settings
(:mod:`rig.config.plan_settings`); the plan is built with :func:`rig.config.plans.plan_from_dict`,
the reader of plan files, so the form accepts what a plan file accepts and shows an error at the
key path it carries.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rig.config.plan_settings import (
    AcquisitionSettings,
    ControlPolicy,
    ExcitationSettings,
    FrequencyPlan,
    FrequencyRange,
    Limits,
    PretestSettings,
    RandomAcquisition,
    RandomExcitation,
    ResponseLimit,
)
from rig.config.plans import (
    Plan,
    SteppedSinePlan,
    builtin_plans,
    describe_plan,
    load_plan,
    plan_from_dict,
)
from rig.gui.forms import RowsTable, SettingsForm
from rig.gui.settings_editor import SettingsEditor
from rig.gui.settings_fields import Field, dataclass_fields

__all__ = ["PlanEditor"]


def _general() -> list[Field]:
    labels = {"setup": "setup expected", "points": "points recorded"}
    return dataclass_fields(SteppedSinePlan, labels=labels)


def _limits(form: SettingsForm) -> None:
    form.add_rows(
        "Limits",
        "limits.response",
        "response limits (alarm warns, abort ends the run)",
        RowsTable(dataclass_fields(ResponseLimit)),
    )


def stepped_form() -> SettingsForm:
    """The form of a stepped-sine plan."""
    form = SettingsForm(
        [
            ("Plan", _general()),
            ("Excitation", dataclass_fields(ExcitationSettings, "excitation")),
            (
                "Frequencies",
                dataclass_fields(
                    FrequencyPlan, "frequencies", labels={"direction": "sweep direction"}
                ),
            ),
            ("Limits", dataclass_fields(Limits, "limits")),
            ("Acquisition", dataclass_fields(AcquisitionSettings, "acquisition")),
            ("Force control", dataclass_fields(ControlPolicy, "control")),
            ("Pre-test", dataclass_fields(PretestSettings, "pretest")),
        ]
    )
    form.add_rows(
        "Frequencies",
        "frequencies.ranges",
        "ranges (their union is swept; shared frequencies once)",
        RowsTable(dataclass_fields(FrequencyRange)),
    )
    _limits(form)
    return form


def random_form() -> SettingsForm:
    """The form of a random (linear) plan."""
    form = SettingsForm(
        [
            ("Plan", _general()),
            ("Excitation", dataclass_fields(RandomExcitation, "excitation")),
            ("Limits", dataclass_fields(Limits, "limits")),
            ("Acquisition", dataclass_fields(RandomAcquisition, "acquisition")),
            ("Pre-test", dataclass_fields(PretestSettings, "pretest")),
        ]
    )
    _limits(form)
    return form


class PlanEditor(SettingsEditor):
    """Choose, open, edit, check and save a test plan."""

    source = "plan form"
    what = "plan"

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.add_form("stepped-sine", stepped_form())
        self.add_form("random", random_form())

    def builtins(self) -> Mapping[str, Path]:
        return builtin_plans()

    def read(self, name_or_path: str) -> Plan:
        return load_plan(name_or_path)

    def kind_of(self, value: Plan) -> str:
        return value.kind

    def build(self, doc: dict[str, Any]) -> Plan:
        return plan_from_dict({**doc, "kind": self.kind}, self.source)

    def describe(self, value: Plan) -> str:
        """The plan in a line, with the acquisition time a dry run gives (rig.run.dry_run)."""
        from analysis.progress import format_duration
        from rig.run.dry_run import dry_run

        try:
            seconds = dry_run(value).seconds
        except Exception as exc:  # noqa: BLE001 - the summary line must not stop the editor
            return f"{describe_plan(value)}; the dry run failed: {exc}"
        least = "at least " if isinstance(value, SteppedSinePlan) else ""
        return f"{describe_plan(value)}; acquisition {least}{format_duration(seconds)}"
