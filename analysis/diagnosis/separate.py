"""The measurement that separates tied candidates, written as a test plan.

:func:`analysis.diagnosis.discriminate.discriminate` names the configuration (sensor, level,
frequency range) where the tied candidates' predictions differ most; this module writes it as a
stepped-sine plan in the rig's plan file format (``rig/plans/*.toml``, documented in
``docs/acquisition.md``), so the rig can run it and the diagnosis rank again on both files. The plan
keeps the file's drive (actuator, force orders and their relative amplitudes) and sensors, adds
the proposed sensor, and steps the proposed range at the proposed level; every other setting is
the plan format's default. The analysis writes the file without importing the rig; the rig's
tests read it back with the rig's own reader.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from analysis.measurement_file import SteppedSineData

__all__ = ["separating_plan", "write_separating_plan"]


def separating_plan(recommendation: dict, data: SteppedSineData, name: str = "separate") -> dict:
    """The plan document (a dict for ``tomli_w``) of a discrimination's best configuration.

    Parameters
    ----------
    recommendation : dict
        :func:`~analysis.diagnosis.discriminate.discriminate`'s result (``best`` with
        ``sensor``, ``level_n``, ``start_hz``, ``stop_hz``, ``step_hz``; ``candidates``).
    data : SteppedSineData
        The file the tie came from (its drive, orders and sensors are kept).
    name : str
        The plan's name.
    """
    best = recommendation.get("best")
    missing = [k for k in ("sensor", "level_n", "start_hz", "stop_hz", "step_hz") if k not in best]
    if missing:
        raise ValueError(f"recommendation's best configuration lacks {', '.join(missing)}")
    orders = [Fraction(o).limit_denominator(1000) for o in data.orders]
    one = Fraction(1)
    if one not in orders:
        raise ValueError("the file's force has no fundamental (order 1) to scale the plan by")
    targets = np.asarray(data.force_targets[0])
    ratio = targets / targets[orders.index(one)]  # the plan gives amplitudes relative to it
    points = sorted({int(ch.point) for ch in data.channels} | {int(best["sensor"])})
    tied = "; ".join(recommendation.get("candidates", []))
    doc: dict[str, Any] = {
        "name": name,
        "kind": "stepped-sine",
        "description": (
            f"separates {tied}: point {best['sensor']}, {best['level_n']:g} N, "
            f"{best['start_hz']:g}-{best['stop_hz']:g} Hz"
        ),
        "points": points,
        "excitation": {
            "orders": [int(o) if o.denominator == 1 else str(o) for o in orders],
            "relative_amplitudes": [float(abs(r)) for r in ratio],
            "phases_deg": [float(np.degrees(np.angle(r))) for r in ratio],
            "levels_n": [float(best["level_n"])],
        },
        "frequencies": {
            "direction": "up",
            "ranges": [
                {
                    "start_hz": float(best["start_hz"]),
                    "stop_hz": float(best["stop_hz"]),
                    "step_hz": float(best["step_hz"]),
                }
            ],
        },
    }
    return doc


def write_separating_plan(
    path: str | Path, recommendation: dict, data: SteppedSineData, name: str | None = None
) -> Path:
    """Write :func:`separating_plan` to ``path`` (TOML); returns the path."""
    path = Path(path)
    doc = separating_plan(recommendation, data, name or path.stem)
    header = (
        "# The measurement that separates the tied candidates of a diagnosis: run it with\n"
        "# `python -m rig separate RUN --model MODEL` (or `python -m rig run PLAN`).\n"
    )
    path.write_text(header + tomli_w.dumps(doc))
    return path
