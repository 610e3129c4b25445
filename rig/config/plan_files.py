"""Reading test plans from TOML: built-in plans by name, plan files by path, stored plans.

Every error is a :class:`~rig.config.tomlconfig.ConfigError` naming the source and the key path. The
file layout is described in :mod:`rig.config.plans`.
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction
from importlib import resources
from pathlib import Path
from typing import Any

from rig.config.plan_settings import (
    DIRECTIONS,
    AcquisitionSettings,
    ControlPolicy,
    ControlSettings,
    ExcitationSettings,
    FrequencyPlan,
    FrequencyRange,
    Limits,
    PretestSettings,
    RandomAcquisition,
    RandomExcitation,
    ResponseLimit,
)
from rig.config.plan_types import Plan, RandomPlan, SteppedSinePlan
from rig.config.tomlconfig import ConfigError, Table, read_toml
from rig.signals.multisine import as_orders

__all__ = ["builtin_plans", "describe_plan", "load_plan", "plan_from_dict"]


def _orders(table: Table, key: str) -> tuple[Fraction, ...]:
    values = table.array(key, ["1", "2", "3"])
    out = []
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, int | str | float):
            raise table.error(
                f"{key}[{i}]", f"expected an integer or a string like '1/2', got {v!r}"
            )
        with table.checking(f"{key}[{i}]"):
            out.append(as_orders([v], "order")[0])
    with table.checking(key):
        return as_orders(out, "orders")


def _dataclass_fields(table: Table, cls: type, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """Read every field of ``cls`` present in ``table`` with the type of its default."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.name in skip or f.name not in table:
            continue
        default = f.default if f.default is not dataclasses.MISSING else None
        if isinstance(default, bool):
            out[f.name] = table.flag(f.name)
        elif isinstance(default, int):
            out[f.name] = table.integer(f.name)
        elif isinstance(default, float) or default is None:
            out[f.name] = table.number(f.name)
        else:
            out[f.name] = table.text(f.name)
    return out


def _limits(table: Table) -> Limits:
    response = []
    for t in table.tables("response"):
        kwargs = _dataclass_fields(t, ResponseLimit)
        t.finish()
        response.append(t.build(ResponseLimit, **kwargs))
    kwargs = {"drive_peak_v": table.number("drive_peak_v", 1.0, positive=True)}
    table.finish()
    return table.build(Limits, response=tuple(response), **kwargs)


def _pretest(table: Table) -> PretestSettings:
    kwargs = _dataclass_fields(table, PretestSettings)
    table.finish()
    return table.build(PretestSettings, **kwargs)


def _frequencies(table: Table) -> FrequencyPlan:
    ranges = []
    for t in table.tables("ranges", required=True):
        kwargs = {k: t.number(k, positive=True) for k in ("start_hz", "stop_hz", "step_hz")}
        t.finish()
        ranges.append(t.build(FrequencyRange, **kwargs))
    direction = table.text("direction", "up", choices=DIRECTIONS)
    table.finish()
    return table.build(FrequencyPlan, ranges=tuple(ranges), direction=direction)


def _excitation(table: Table) -> ExcitationSettings:
    orders = _orders(table, "orders")
    default_amps = tuple(1.0 if o == 1 else 0.02 for o in orders)
    kwargs = {
        "orders": orders,
        "relative_amplitudes": table.numbers("relative_amplitudes", default_amps),
        "phases_deg": table.numbers("phases_deg", None),
        "levels_n": table.numbers("levels_n", positive=True),
    }
    table.finish()
    return table.build(ExcitationSettings, **kwargs)


def _control(table: Table, orders: tuple[Fraction, ...], drive_peak_v: float) -> ControlPolicy:
    policy = {
        "uncertainty_factor": table.number("uncertainty_factor", 2.0, minimum=0.0),
        "warm_start": table.flag("warm_start", True),
        "on_divergence": table.text("on_divergence", "abort", choices=("abort", "record")),
        "divergence_abort_error": table.number("divergence_abort_error", 0.5, positive=True),
        "restart_after": table.integer("restart_after", 4, minimum=0),
    }
    for name in ("orders", "max_drive_v"):
        if name in table:
            where = "excitation.orders" if name == "orders" else "limits.drive_peak_v"
            raise table.error(name, f"set by {where}, not here")
    kwargs = _dataclass_fields(table, ControlSettings, skip=("orders", "max_drive_v"))
    table.finish()
    settings = table.build(ControlSettings, orders=orders, max_drive_v=drive_peak_v, **kwargs)
    return table.build(ControlPolicy, settings=settings, **policy)


def _common(root: Table) -> dict[str, Any]:
    return {
        "name": root.text("name"),
        "description": root.text("description", ""),
        "setup": root.text("setup", "reference"),
        "points": root.integers("points", minimum=0),
        "sample_rate_hz": root.number("sample_rate_hz", 0.0, minimum=0.0),
    }


def plan_from_dict(data: dict[str, Any], source: str = "plan") -> Plan:
    """Build and validate a plan from parsed TOML or a plan's ``to_dict()``.

    Raises
    ------
    ConfigError
        Naming ``source`` and the key of the first problem.
    """
    root = Table(data, source)
    kind = root.text("kind", "stepped-sine", choices=("stepped-sine", "random"))
    common = _common(root)
    limits = _limits(root.table("limits"))
    pretest = _pretest(root.table("pretest"))
    if kind == "stepped-sine":
        excitation = _excitation(root.table("excitation", required=True))
        frequencies = _frequencies(root.table("frequencies", required=True))
        acq_t = root.table("acquisition")
        acquisition = acq_t.build(
            AcquisitionSettings, **_dataclass_fields(acq_t, AcquisitionSettings)
        )
        acq_t.finish()
        control = _control(root.table("control"), excitation.orders, limits.drive_peak_v)
        root.finish()
        return root.build(
            SteppedSinePlan,
            excitation=excitation,
            frequencies=frequencies,
            acquisition=acquisition,
            control=control,
            limits=limits,
            pretest=pretest,
            **common,
        )
    ex_t = root.table("excitation")
    excitation = ex_t.build(RandomExcitation, **_dataclass_fields(ex_t, RandomExcitation))
    ex_t.finish()
    acq_t = root.table("acquisition")
    acquisition = acq_t.build(RandomAcquisition, **_dataclass_fields(acq_t, RandomAcquisition))
    acq_t.finish()
    root.finish()
    return root.build(
        RandomPlan,
        excitation=excitation,
        acquisition=acquisition,
        limits=limits,
        pretest=pretest,
        **common,
    )


def builtin_plans() -> dict[str, Path]:
    """Name -> file of the plans shipped in ``rig/plans``."""
    folder = resources.files("rig") / "plans"
    return {Path(str(p)).stem: Path(str(p)) for p in folder.iterdir() if p.name.endswith(".toml")}


def load_plan(name_or_path: str | Path) -> Plan:
    """Load a built-in plan by name or a plan file by path.

    Raises
    ------
    ConfigError
        If the name is unknown (the message lists the built-in plans), the file cannot be read,
        or a setting is invalid (the message names the file and the key).
    """
    text = str(name_or_path)
    builtins = builtin_plans()
    if text in builtins:
        path, label = builtins[text], f"plan {text!r} ({builtins[text]})"
    else:
        path = Path(text)
        if not path.exists():
            raise ConfigError(
                f"plan {text!r}: no such file and not a built-in plan "
                f"(built-in: {', '.join(sorted(builtins))})"
            )
        label = f"plan file {path}"
    return plan_from_dict(read_toml(path, label), label)


def describe_plan(plan: Plan) -> str:
    """One line: kind, size and what is measured."""
    pts = ",".join(map(str, plan.points))
    if isinstance(plan, SteppedSinePlan):
        f = plan.frequencies.frequencies_hz()
        levels = "/".join(f"{v:g}" for v in plan.levels_n)
        orders = ",".join(str(o) for o in plan.excitation.orders)
        return (
            f"stepped-sine: {plan.n_steps} steps ({f.size} frequencies {f[0]:g}-{f[-1]:g} Hz "
            f"{plan.frequencies.direction} x levels {levels} N), orders {orders}, points {pts}"
        )
    ex = plan.excitation
    return (
        f"random: {ex.signal} {ex.f_lo_hz:g}-{ex.f_hi_hz:g} Hz at {ex.force_rms_n:g} N rms, "
        f"{plan.acquisition.average_records} x {ex.record_s:g} s records, points {pts}"
    )
