"""Records that go into a measurement file: channels, actuator, one stepped-sine step, a random FRF.

All are frozen dataclasses validated on construction; a bad field raises
:class:`~analysis.measurement_file.schema.FieldValueError` (a ``ValueError``) naming the field,
what was expected and what was found. Arrays are stored as read-only copies.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from .schema import (
    DIRECTIONS,
    EXTRA_FORCE_FIELDS,
    QUANTITIES,
    ROLES,
    STEP_FIELDS,
    FieldValueError,
    check_array,
    check_float,
    check_int,
    check_text,
    is_copy,
)

__all__ = [
    "Actuator",
    "ChannelInfo",
    "RandomFRF",
    "ESTIMATORS",
    "StepRecord",
    "check_channels",
    "check_extra_orders",
    "check_plan",
    "drive_force_index",
]

ESTIMATORS = ("H1", "periodic")
"""FRF estimators of a random run: ``"H1"`` (Welch cross- over auto-spectrum) and
``"periodic"`` (ratio of the period-averaged spectra of a periodic excitation)."""


@dataclass(frozen=True)
class ChannelInfo:
    """One acquired channel: a row of ``/setup/channels``.

    Attributes
    ----------
    name : str
        Unique, non-empty channel name.
    point : int
        Measurement point number (>= 0).
    direction : str
        ``"x" | "y" | "z" | "rx" | "ry" | "rz"``, with a leading ``"-"`` if the sensor axis is
        reversed.
    quantity : str
        ``"force" | "acceleration" | "velocity" | "displacement" | "voltage"``.
    unit : str
        SI unit of the stored data, e.g. ``"m/s^2"``, ``"N"``; ``"1"`` if dimensionless.
    sensitivity : float
        Sensor sensitivity, for documentation only (stored data are already in ``unit``).
    sensitivity_unit : str
        Unit of ``sensitivity``, e.g. ``"mV/g"``.
    role : str
        ``"drive-force" | "drive-acceleration" | "response" | "reference"``. A drive-force
        channel must measure a force.
    mass_kg : float
        Sensor mass added to the structure at ``point`` [kg]; 0 if negligible or unknown.
    serial : str
        Serial number, may be empty.
    """

    name: str
    point: int
    direction: str
    quantity: str
    unit: str
    sensitivity: float
    sensitivity_unit: str
    role: str
    mass_kg: float = 0.0
    serial: str = ""

    def __post_init__(self) -> None:
        owner = f"ChannelInfo {self.name!r}"
        name = check_text(self.name, owner="ChannelInfo", field="name")
        if not name.strip():
            raise FieldValueError("ChannelInfo", "name", "a non-empty name", repr(name))
        fix: dict[str, Any] = {
            "point": check_int(self.point, owner=owner, field="point", minimum=0),
            "direction": check_text(
                self.direction, owner=owner, field="direction", allowed=DIRECTIONS
            ),
            "quantity": check_text(
                self.quantity, owner=owner, field="quantity", allowed=QUANTITIES
            ),
            "unit": check_text(self.unit, owner=owner, field="unit"),
            "sensitivity": check_float(self.sensitivity, owner=owner, field="sensitivity"),
            "sensitivity_unit": check_text(
                self.sensitivity_unit, owner=owner, field="sensitivity_unit"
            ),
            "role": check_text(self.role, owner=owner, field="role", allowed=ROLES),
            "mass_kg": check_float(self.mass_kg, owner=owner, field="mass_kg", minimum=0.0),
            "serial": check_text(self.serial, owner=owner, field="serial"),
        }
        if not fix["unit"].strip():
            raise FieldValueError(owner, "unit", "a non-empty SI unit", repr(self.unit))
        if fix["role"] == "drive-force" and fix["quantity"] != "force":
            raise FieldValueError(
                owner,
                "quantity",
                "'force' for a channel of role 'drive-force'",
                repr(self.quantity),
            )
        for key, value in fix.items():
            object.__setattr__(self, key, value)


@dataclass(frozen=True)
class Actuator:
    """Where the shaker acts: ``/setup/actuator``.

    Attributes
    ----------
    point : int
        Measurement point number of the drive point (>= 0).
    direction : str
        Direction of the applied force, one of the channel directions.
    static_stiffness_n_per_m : float
        Stiffness with which the shaker holds the drive point at its mean position (its
        suspension in series with the stinger) [N/m]; 0 when unknown or negligible. The mean
        force is not measured (AC-coupled channels), so a model needs this to place the mean
        response of a structure with a one-sided contact (optional attribute
        ``static_stiffness_n_per_m`` of ``/setup/actuator``; absent means 0).
    """

    point: int
    direction: str
    static_stiffness_n_per_m: float = 0.0

    def __post_init__(self) -> None:
        point = check_int(self.point, owner="Actuator", field="point", minimum=0)
        direction = check_text(
            self.direction, owner="Actuator", field="direction", allowed=DIRECTIONS
        )
        static = check_float(
            self.static_stiffness_n_per_m,
            owner="Actuator",
            field="static_stiffness_n_per_m",
            minimum=0.0,
        )
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "static_stiffness_n_per_m", static)


def check_channels(channels: Iterable[ChannelInfo]) -> tuple[ChannelInfo, ...]:
    """Validate a channel set: at least one, unique names, exactly one drive-force channel.

    Returns
    -------
    tuple of ChannelInfo
        The channels in acquisition order.
    """
    if isinstance(channels, ChannelInfo):
        raise FieldValueError("channels", "type", "a sequence of ChannelInfo", "one ChannelInfo")
    chans = tuple(channels)
    if not chans:
        raise FieldValueError("channels", "length", "at least one channel", "none")
    for i, ch in enumerate(chans):
        if not isinstance(ch, ChannelInfo):
            raise FieldValueError("channels", f"[{i}]", "a ChannelInfo", type(ch).__name__)
    names = [ch.name for ch in chans]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FieldValueError("channels", "name", "unique names", f"repeated {dup}")
    drive = [ch.name for ch in chans if ch.role == "drive-force"]
    if len(drive) != 1:
        raise FieldValueError(
            "channels", "role", "exactly one channel of role 'drive-force'", f"{drive or 'none'}"
        )
    return chans


def drive_force_index(channels: tuple[ChannelInfo, ...]) -> int:
    """Index of the (single) drive-force channel."""
    return next(i for i, ch in enumerate(channels) if ch.role == "drive-force")


def _check_orders(
    num_in: Any, den_in: Any, name: str, owner: str
) -> tuple[np.ndarray, np.ndarray, list[Fraction]]:
    """``(num, den, fractions)`` of the datasets ``<name>_num`` and ``<name>_den``: int64,
    same shape, both >= 1, distinct fractions."""
    num = check_array(
        num_in, dtype="int64", shape=(None,), check="at-least-one", owner=owner, field=f"{name}_num"
    )
    den = check_array(
        den_in,
        dtype="int64",
        shape=num.shape,
        check="at-least-one",
        owner=owner,
        field=f"{name}_den",
    )
    orders = [Fraction(int(a), int(b)) for a, b in zip(num, den, strict=True)]
    repeated = sorted({str(x) for x in orders if orders.count(x) > 1})
    if repeated:
        raise FieldValueError(owner, f"{name}_num", "distinct orders", f"repeated {repeated}")
    return num, den, orders


def check_plan(
    levels_n: Any, orders_num: Any, orders_den: Any, force_targets: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validate the plan arrays of a stepped-sine file.

    Parameters
    ----------
    levels_n : array_like, shape (L,), N
        Target fundamental force amplitudes, > 0, at least one.
    orders_num, orders_den : array_like of int, shape (H,)
        Orders as fractions ``orders_num / orders_den``, both >= 1, distinct values.
    force_targets : array_like, shape (L, H), complex, N
        Target force phasors per level and order.

    Returns
    -------
    tuple of ndarray
        ``(levels, orders_num, orders_den, force_targets)`` as read-only contract-typed copies.

    Raises
    ------
    FieldValueError
        With ``field`` the dataset name (``levels``, ``orders_num``, ...).
    """
    o = "stepped-sine plan"
    levels = check_array(
        levels_n, dtype="float64", shape=(None,), check="positive", owner=o, field="levels"
    )
    if levels.size == 0:
        raise FieldValueError(o, "levels", "at least one level", "shape (0,)")
    num, den, _ = _check_orders(orders_num, orders_den, "orders", o)
    if num.size == 0:
        raise FieldValueError(o, "orders_num", "at least one order", "shape (0,)")
    targets = check_array(
        force_targets,
        dtype="complex128",
        shape=(levels.size, num.size),
        owner=o,
        field="force_targets",
    )
    return levels, num, den, targets


def check_extra_orders(
    extra_orders_num: Any, extra_orders_den: Any, orders_num: np.ndarray, orders_den: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Validate the extra orders of a stepped-sine file (the drive force recorded there).

    Parameters
    ----------
    extra_orders_num, extra_orders_den : array_like of int, shape (E,)
        Orders as fractions, both >= 1, distinct and none of them an order of the file
        (``orders_num / orders_den``); ``E`` may be 0.
    orders_num, orders_den : ndarray of int64, shape (H,)
        The file's orders (validated by :func:`check_plan`).

    Returns
    -------
    tuple of ndarray
        ``(extra_orders_num, extra_orders_den)`` as read-only int64 copies.

    Raises
    ------
    FieldValueError
        With ``field`` ``extra_orders_num`` or ``extra_orders_den``.
    """
    o = "stepped-sine plan"
    if np.size(extra_orders_num) == 0 and np.size(extra_orders_den) == 0:
        extra_orders_num = extra_orders_den = np.zeros(0, np.int64)
    num, den, extra = _check_orders(extra_orders_num, extra_orders_den, "extra_orders", o)
    orders = {Fraction(int(a), int(b)) for a, b in zip(orders_num, orders_den, strict=True)}
    shared = sorted(str(x) for x in set(extra) & orders)
    if shared:
        raise FieldValueError(
            o, "extra_orders_num", "orders the drive does not contain", f"{shared} (in /orders)"
        )
    return num, den


@dataclass(frozen=True, eq=False)
class StepRecord:
    """One completed step of a stepped-sine run: one row of every ``/steps`` dataset.

    ``C`` is the number of channels, ``H`` the number of orders. Phasors follow the contract:
    amplitude (not RMS) phasors of x(t) = Re{sum_k X_k exp(i omega_k t)}, all sharing one time
    origin; stds are standard errors of the averaged complex phasor (0 allowed).

    Attributes
    ----------
    plan_index : int
        Index of the step in the plan (>= 0, unique within a file).
    level_index : int
        Row of ``/levels``.
    sweep_direction : int
        +1 up, -1 down.
    frequency_target_hz : float
        Planned fundamental frequency [Hz], > 0.
    frequency_hz : float
        Realised fundamental frequency on the DAQ clock [Hz], > 0.
    force : ndarray, shape (H,), complex, N
        Drive-force phasors: a copy of the drive-force channel's row of ``response``.
    force_std : ndarray, shape (H,), N
    response : ndarray, shape (C, H), complex, channel units
        Every channel in table order (the drive-force channel included).
    response_std : ndarray, shape (C, H), channel units
    drive : ndarray, shape (H,), complex, V
        Output voltage phasors that produced this step.
    n_blocks : int
        Blocks averaged, >= 1.
    control_iterations : int
        Force-control iterations, >= 0.
    control_converged : bool
    control_error : float
        Final max_k |F_k - F_target,k| / |F_target,1|, >= 0.
    timestamp : float
        POSIX time of completion [s]; defaults to now.
    extra_force, extra_force_std : ndarray, shape (E,), optional
        Drive-force phasors and their standard errors at the file's extra orders (orders the
        drive does not contain); both or neither.
    """

    plan_index: int
    level_index: int
    sweep_direction: int
    frequency_target_hz: float
    frequency_hz: float
    force: np.ndarray
    force_std: np.ndarray
    response: np.ndarray
    response_std: np.ndarray
    drive: np.ndarray
    n_blocks: int
    control_iterations: int
    control_converged: bool
    control_error: float
    timestamp: float = field(default_factory=time.time)
    extra_force: np.ndarray | None = None
    extra_force_std: np.ndarray | None = None

    def __post_init__(self) -> None:
        owner = f"StepRecord (plan_index {self.plan_index!r})"
        values: dict[str, Any] = {}
        extra = self.extra_force is not None or self.extra_force_std is not None
        for spec in STEP_FIELDS + (EXTRA_FORCE_FIELDS if extra else ()):
            shape = tuple(None for _ in spec.dims)
            arr = check_array(
                getattr(self, spec.field),
                dtype=spec.dtype,
                shape=shape,
                check=spec.check,
                owner=owner,
                field=spec.field,
            )
            values[spec.field] = arr if arr.ndim else arr.item()
        n_orders = values["force"].shape[0]
        if n_orders == 0:
            raise FieldValueError(owner, "force", "at least one order", "shape (0,)")
        for name in ("force_std", "drive"):
            if values[name].shape != (n_orders,):
                raise FieldValueError(
                    owner, name, f"shape ({n_orders},) like force", f"shape {values[name].shape}"
                )
        resp = values["response"]
        if resp.shape[1] != n_orders or resp.shape[0] == 0:
            raise FieldValueError(
                owner, "response", f"shape (C, {n_orders}) with C >= 1", f"shape {resp.shape}"
            )
        if values["response_std"].shape != resp.shape:
            raise FieldValueError(
                owner,
                "response_std",
                f"shape {resp.shape} like response",
                f"shape {values['response_std'].shape}",
            )
        if extra and values["extra_force_std"].shape != values["extra_force"].shape:
            raise FieldValueError(
                owner,
                "extra_force_std",
                f"shape {values['extra_force'].shape} like extra_force",
                f"shape {values['extra_force_std'].shape}",
            )
        for key, value in values.items():
            object.__setattr__(self, key, value)

    def check_drive_force(self, index: int) -> None:
        """Check that ``force`` and ``force_std`` copy row ``index`` of the response arrays."""
        owner = f"StepRecord (plan_index {self.plan_index})"
        if not is_copy(self.force, self.response[index]):
            raise FieldValueError(
                owner,
                "force",
                f"a copy of response[{index}] (the drive-force channel)",
                f"{self.force} vs {self.response[index]}",
            )
        if not is_copy(self.force_std, self.response_std[index]):
            raise FieldValueError(
                owner,
                "force_std",
                f"a copy of response_std[{index}] (the drive-force channel)",
                f"{self.force_std} vs {self.response_std[index]}",
            )


@dataclass(frozen=True, eq=False)
class RandomFRF:
    """The frequency-response estimate of a random-excitation run: ``/frf``.

    Attributes
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
        Strictly increasing, >= 0.
    h1 : ndarray, shape (nf, C), complex, channel unit per N
        Every channel in table order per unit drive force; the drive-force column is 1.
    coherence : ndarray, shape (nf, C)
        Ordinary coherence with the drive force, within [0, 1].
    force_psd : ndarray, shape (nf,), N^2/Hz
        One-sided auto spectral density of the drive force, >= 0.
    n_averages : int
        Number of averaged segments, >= 1.
    window : str
        Name of the window, e.g. ``"hann"``.
    overlap : float
        Segment overlap as a fraction, 0 <= overlap < 1.
    fs_hz : float
        Sampling rate [Hz], > 0.
    rms_force_n : float
        RMS of the drive force [N], >= 0.
    estimator : str
        How ``h1`` was estimated (:data:`ESTIMATORS`): ``"H1"``, the Welch cross-spectrum over
        the force's auto-spectrum, or ``"periodic"``, the ratio of the spectra averaged over
        the periods of a periodic excitation (not biased by noise on the force, where H1 is
        biased low by ``1 / (1 + S_nn / S_ff)``).
    """

    frequency_hz: np.ndarray
    h1: np.ndarray
    coherence: np.ndarray
    force_psd: np.ndarray
    n_averages: int
    window: str
    overlap: float
    fs_hz: float
    rms_force_n: float

    estimator: str = "H1"

    def __post_init__(self) -> None:
        o = "RandomFRF"
        freq = check_array(
            self.frequency_hz,
            dtype="float64",
            shape=(None,),
            check="increasing",
            owner=o,
            field="frequency_hz",
        )
        if freq.size == 0 or freq[0] < 0:
            raise FieldValueError(o, "frequency_hz", "at least one frequency >= 0", f"{freq}")
        nf = freq.shape[0]
        h1 = check_array(self.h1, dtype="complex128", shape=(nf, None), owner=o, field="h1")
        if h1.shape[1] == 0:
            raise FieldValueError(o, "h1", "at least one channel column", f"shape {h1.shape}")
        fix: dict[str, Any] = {
            "frequency_hz": freq,
            "h1": h1,
            "coherence": check_array(
                self.coherence,
                dtype="float64",
                shape=h1.shape,
                check="unit-interval",
                owner=o,
                field="coherence",
            ),
            "force_psd": check_array(
                self.force_psd,
                dtype="float64",
                shape=(nf,),
                check="nonnegative",
                owner=o,
                field="force_psd",
            ),
            "n_averages": check_int(self.n_averages, owner=o, field="n_averages", minimum=1),
            "window": check_text(self.window, owner=o, field="window"),
            "overlap": check_float(self.overlap, owner=o, field="overlap", minimum=0, below=1),
            "fs_hz": check_float(self.fs_hz, owner=o, field="fs_hz", positive=True),
            "rms_force_n": check_float(self.rms_force_n, owner=o, field="rms_force_n", minimum=0),
        }
        if not fix["window"].strip():
            raise FieldValueError(o, "window", "a window name", repr(self.window))
        if self.estimator not in ESTIMATORS:
            raise FieldValueError(o, "estimator", f"one of {ESTIMATORS}", repr(self.estimator))
        for key, value in fix.items():
            object.__setattr__(self, key, value)

    def check_drive_force(self, index: int) -> None:
        """Check that the drive-force column ``index`` of ``h1`` is 1 (to rounding)."""
        col = self.h1[:, index]
        if not np.allclose(col, 1.0, rtol=0, atol=1e-6):
            bad = int(np.argmax(np.abs(col - 1.0)))
            raise FieldValueError(
                "RandomFRF",
                "h1",
                f"1 in column {index} (the drive-force channel)",
                f"{col[bad]!r} at row {bad}",
            )
