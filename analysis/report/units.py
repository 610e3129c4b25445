"""Units of the numbers a report shows: the unit a value is displayed in, and its text forms."""

from __future__ import annotations

import re

__all__ = ["display_unit", "html_unit", "mathtext_unit"]

#: SI unit -> (factor to the displayed unit, displayed unit): a gap reads in mm, a modulus in GPa.
DISPLAY = {
    "m": (1e3, "mm"),
    "Pa": (1e-9, "GPa"),
}

_POWER = re.compile(r"\^(-?[0-9.]+)")


def display_unit(unit: str | None) -> tuple[float, str]:
    """(factor, unit) a value in ``unit`` is shown with: ``value * factor`` in that unit."""
    unit = (unit or "").strip()
    return DISPLAY.get(unit, (1.0, unit))


def mathtext_unit(unit: str | None) -> str:
    """``"N s^2/m^2"`` -> matplotlib mathtext (``N s$^{2}$/m$^{2}$``)."""
    return _POWER.sub(lambda m: f"$^{{{m.group(1)}}}$", unit or "")


def html_unit(unit: str | None) -> str:
    """``"N s^2/m^2"`` -> HTML (``N&#8239;s<sup>2</sup>/m<sup>2</sup>``), text escaped."""
    import html

    text = html.escape(unit or "")
    text = _POWER.sub(lambda m: f"<sup>{m.group(1)}</sup>", text)
    return text.replace(" ", "&#8239;")  # a narrow space keeps N s together
