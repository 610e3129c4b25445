"""Reading test plans from TOML: built-in plans by name, plan files by path, stored plans.

A plan's data is read by the plan classes' own declarations (:mod:`rig.config.settings`):
every error is a :class:`~rig.config.tomlconfig.ConfigError` naming the source and the key
path. The file layout is described in :mod:`rig.config.plans`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rig.config.plan_types import Plan, RandomPlan, SteppedSinePlan
from rig.config.settings import build
from rig.config.tomlconfig import ConfigError, builtin_files, read_named

__all__ = ["builtin_plans", "describe_plan", "load_plan", "plan_from_dict"]

_KINDS: dict[str, type[SteppedSinePlan] | type[RandomPlan]] = {
    cls.kind: cls for cls in (SteppedSinePlan, RandomPlan)
}


def plan_from_dict(data: dict[str, Any], source: str = "plan") -> Plan:
    """Build and validate a plan from parsed TOML or a plan's ``to_dict()``.

    Raises
    ------
    ConfigError
        Naming ``source`` and the key of the first problem (:attr:`ConfigError.path`).
    """
    if not isinstance(data, dict):
        raise ConfigError(source, (), f"expected a table, got {data!r}")
    kind = data.get("kind", SteppedSinePlan.kind)
    if not isinstance(kind, str) or kind not in _KINDS:
        choices = ", ".join(map(repr, _KINDS))
        raise ConfigError(source, ("kind",), f"expected one of {choices}, got {kind!r}")
    return build(_KINDS[kind], {k: v for k, v in data.items() if k != "kind"}, source)


def builtin_plans() -> dict[str, Path]:
    """Name -> file of the plans shipped in ``rig/plans``."""
    return builtin_files("plans")


def load_plan(name_or_path: str | Path) -> Plan:
    """Load a built-in plan by name or a plan file by path.

    Raises
    ------
    ConfigError
        If the name is unknown (the message lists the built-in plans), the file cannot be read,
        or a setting is invalid (the message names the file and the key).
    """
    return plan_from_dict(*read_named("plan", name_or_path, builtin_plans()))


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
