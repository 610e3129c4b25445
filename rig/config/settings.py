"""The settings layer of the lab application: plans and lab setups declared once.

The generic layer (:func:`settings`, :func:`build`, :func:`dump`, :func:`declared_fields`,
:class:`ConfigError` with its key path, :class:`SettingError` and the strict scalar types) is
:mod:`analysis.settings`, shared with the model file and the simulator's truth files; this module
adds the harmonic-order type :data:`Orders` and keeps the names the rig's modules import.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Annotated, Any

from pydantic import BeforeValidator, PlainSerializer

from analysis.settings import (
    SETTINGS,
    ConfigError,
    DeclaredField,
    Flag,
    Integer,
    KeyPath,
    NonNegative,
    Number,
    Positive,
    SettingError,
    Text,
    build,
    declare,
    declared_fields,
    dump,
    settings,
)
from rig.signals.multisine import as_orders

__all__ = [
    "SETTINGS",
    "ConfigError",
    "DeclaredField",
    "Flag",
    "Integer",
    "KeyPath",
    "NonNegative",
    "Number",
    "Positive",
    "Orders",
    "SettingError",
    "Text",
    "build",
    "declare",
    "declared_fields",
    "dump",
    "settings",
]


def _orders(value: Any) -> tuple[Fraction, ...]:
    if not isinstance(value, list | tuple):
        raise SettingError((), f"expected an array of orders, got {value!r}")
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, int | str | float | Fraction):
            raise SettingError((i,), f"expected an integer or a string like '1/2', got {v!r}")
        try:
            as_orders([v], "order")
        except (ValueError, ArithmeticError) as exc:  # an infinite order overflows
            raise SettingError((i,), str(exc)) from None
    return as_orders(value, "orders")


#: Harmonic orders: integers or strings like ``"1/2"`` in files, fractions in the objects.
Orders = Annotated[
    tuple[Fraction, ...],
    BeforeValidator(_orders),
    PlainSerializer(lambda orders: [str(o) for o in orders]),
]
