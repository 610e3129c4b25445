"""Export the FRFs of a measurement file as UFF dataset 58 (the exchange format of modal tools).

- A stepped-sine run gives, for every level and sweep direction, every order ``nu`` and every
  channel except the drive force, the multi-harmonic FRF ``H^nu = X_nu / F_nu`` (the channel's
  phasor at order ``nu`` over the drive force's at the same order) against the realised
  fundamental frequency (uneven abscissa). ``load_case_id`` is the level's row + 1 (+100 for
  a downward sweep), ``ver_num`` the order's column + 1; the ID lines say the same in words.
- A random run gives the H1 of every channel except the drive force (even abscissa).

Function type 4 (frequency response function); response node and direction are the channel's
point and axis (1/2/3 for x/y/z, negative for a reversed sensor), reference the actuator's.
Data are in SI units: m/s^2 per N for accelerations (accelerance).

References
----------
Structural Dynamics Research Corporation, *Universal File Format*, dataset 58 (Function at
Nodal DOF). pyuff: https://github.com/ladisk/pyuff
"""

from __future__ import annotations

import logging
from fractions import Fraction
from os import PathLike
from pathlib import Path

import numpy as np

from analysis.measurement_file import RandomData, SteppedSineData, read_measurement

__all__ = ["export_uff", "uff_sets"]

logger = logging.getLogger(__name__)

_DIRECTION_CODES = {"x": 1, "y": 2, "z": 3, "rx": 4, "ry": 5, "rz": 6}
# UFF specific data types of the ordinate numerator, and SI length exponents
_SPEC = {
    "acceleration": (12, 1, "m/s^2"),
    "velocity": (11, 1, "m/s"),
    "displacement": (8, 1, "m"),
    "force": (13, 0, "N"),
    "voltage": (0, 0, "V"),
}


def _direction_code(direction: str) -> int:
    sign = -1 if direction.startswith("-") else 1
    return sign * _DIRECTION_CODES[direction.lstrip("-")]


def _base_set(ch, actuator, data: np.ndarray, x: np.ndarray, even: bool) -> dict:
    spec, length_exp, unit = _SPEC.get(ch.quantity, (0, 0, ch.unit))
    fields = {
        "binary": 0,
        "func_type": 4,
        "rsp_ent_name": ch.name,
        "rsp_node": int(ch.point),
        "rsp_dir": _direction_code(ch.direction),
        "ref_ent_name": "drive",
        "ref_node": int(actuator.point),
        "ref_dir": _direction_code(actuator.direction),
        "abscissa_spec_data_type": 18,
        "abscissa_axis_units_lab": "Hz",
        "ordinate_spec_data_type": spec,
        "ordinate_len_unit_exp": length_exp,
        "ordinate_axis_units_lab": unit,
        "orddenom_spec_data_type": 13,
        "orddenom_force_unit_exp": 1,
        "orddenom_axis_units_lab": "N",
        "data": np.asarray(data, dtype=complex),
        "x": np.asarray(x, dtype=float),
        "abscissa_spacing": 1 if even else 0,
    }
    if even and x.size > 1:
        fields["abscissa_min"] = float(x[0])
        fields["abscissa_inc"] = float(x[1] - x[0])
    return fields


def uff_sets(path: str | PathLike[str]) -> list[dict]:
    """The UFF 58 sets of a measurement file, as keyword dicts for ``pyuff.prepare_58``.

    Returns
    -------
    list of dict
        One per FRF; empty if the file holds no completed step.
    """
    data = read_measurement(path)
    name = Path(path).name
    plan = str(data.config.get("plan", {}).get("name", "")) if data.config else ""
    created = data.created.isoformat(timespec="seconds")
    drive = data.drive_force_index
    sets = []
    if isinstance(data, RandomData):
        for c, ch in enumerate(data.channels):
            if c == drive:
                continue
            s = _base_set(ch, data.actuator, data.h1[:, c], data.frequency_hz, even=True)
            s.update(
                id1=f"H1 {ch.name}/{data.channels[drive].name}",
                id2=f"random test, {data.n_averages} averages, {data.rms_force_n:.3g} N rms",
                id3=f"{name}, created {created}",
                id4="abscissa: frequency; ordinate: H1 (channel per drive force)",
                id5=plan,
                load_case_id=1,
                ver_num=1,
            )
            sets.append(s)
        return sets
    assert isinstance(data, SteppedSineData)
    orders = data.orders
    for li, level in enumerate(data.levels_n):
        for direction in (1, -1):
            part = data.select(level_index=li, sweep_direction=direction)
            if part.n_steps == 0:
                continue
            order = np.argsort(part.frequency_hz, kind="stable")
            f = part.frequency_hz[order]
            sweep = "up" if direction > 0 else "down"
            for k, nu in enumerate(orders):
                for c, ch in enumerate(data.channels):
                    if c == drive:
                        continue
                    h = part.frf(c)[order, k]
                    s = _base_set(ch, data.actuator, h, f, even=False)
                    s.update(
                        id1=f"H^{_order_text(nu)} {ch.name}/{data.channels[drive].name}",
                        id2=f"stepped sine, level {level:g} N, sweep {sweep}",
                        id3=f"{name}, created {created}",
                        id4=(
                            f"abscissa: realised fundamental; ordinate: order {_order_text(nu)} "
                            f"response over order {_order_text(nu)} force"
                        ),
                        id5=plan,
                        load_case_id=li + 1 + (100 if direction < 0 else 0),
                        ver_num=k + 1,
                    )
                    sets.append(s)
    return sets


def _order_text(order: Fraction) -> str:
    return str(Fraction(order))


def export_uff(
    path: str | PathLike[str], uff_path: str | PathLike[str], *, overwrite: bool = False
) -> int:
    """Write the FRFs of a measurement file to a UFF file.

    Parameters
    ----------
    path : path
        Measurement file (stepped-sine or random).
    uff_path : path
        UFF file to write (ASCII).
    overwrite : bool
        Replace an existing UFF file (otherwise refuse).

    Returns
    -------
    int
        Number of datasets written.

    Raises
    ------
    FileExistsError
        If ``uff_path`` exists and ``overwrite`` is false.
    ValueError
        If the file holds no FRF (a stepped-sine run without completed steps).
    """
    import pyuff

    uff_path = Path(uff_path)
    if uff_path.exists():
        if not overwrite:
            raise FileExistsError(f"{uff_path}: file exists (use --overwrite to replace it)")
        uff_path.unlink()
    sets = [pyuff.prepare_58(**s) for s in uff_sets(path)]
    if not sets:
        raise ValueError(f"{path}: no completed step, nothing to export")
    tmp = uff_path.with_name(f".{uff_path.name}.partial")
    tmp.unlink(missing_ok=True)
    try:
        pyuff.UFF(str(tmp)).write_sets(sets, mode="add")
        tmp.replace(uff_path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    logger.info("%d UFF 58 sets written to %s", len(sets), uff_path)
    return len(sets)
