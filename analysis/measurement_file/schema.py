"""Constants, errors and array checks of the measurement-file contract (format_version 2).

Everything the writer and the reader must agree on lives here: the names and allowed values of
the contract (docs/measurement-file.md), the layout of the per-step datasets, and one array
checker used both to validate data before it is written and to validate data read from a file.

The record types users construct (:class:`~analysis.measurement_file.records.ChannelInfo` and
friends) are in :mod:`analysis.measurement_file.records`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np

__all__ = [
    "AXES",
    "CHANNEL_FIELDS",
    "DIRECTIONS",
    "EXIT_STATUSES",
    "FINAL_STATUSES",
    "FORMAT",
    "FORMAT_VERSION",
    "KIND_RANDOM",
    "KIND_STEPPED_SINE",
    "KINDS",
    "QUANTITIES",
    "ROLES",
    "EXTRA_FORCE_FIELDS",
    "STEP_FIELDS",
    "ArraySpec",
    "FieldValueError",
    "MeasurementFileError",
    "channel_table_dtype",
    "check_array",
    "safe_std",
    "step_fields",
]

FORMAT = "rig-measurement"
"""Value of the root attribute ``format``."""

FORMAT_VERSION = 2
"""The ``format_version`` this module writes (and the newest it reads; version 1 files are read
too). Version 2 adds the root attributes ``output_at_zero`` and ``resumes``."""

KIND_STEPPED_SINE = "stepped-sine"
KIND_RANDOM = "random"
KINDS = (KIND_STEPPED_SINE, KIND_RANDOM)

EXIT_STATUSES = ("running", "success", "aborted", "failed")
FINAL_STATUSES = ("success", "aborted", "failed")
"""Statuses a run may end with (``running`` is the status while it is under way)."""

AXES = ("x", "y", "z", "rx", "ry", "rz")
DIRECTIONS = AXES + tuple("-" + a for a in AXES)
"""Allowed sensor and actuator directions; a leading ``-`` marks a reversed sensor axis."""

QUANTITIES = ("force", "acceleration", "velocity", "displacement", "voltage")
ROLES = ("drive-force", "drive-acceleration", "response", "reference")

CHANNEL_FIELDS = (
    "name",
    "point",
    "direction",
    "quantity",
    "unit",
    "sensitivity",
    "sensitivity_unit",
    "role",
    "mass_kg",
    "serial",
)
"""Fields of the ``/setup/channels`` compound table, in the order the contract gives."""

_STRING_FIELDS = frozenset(
    {"name", "direction", "quantity", "unit", "sensitivity_unit", "role", "serial"}
)

_COPY_RTOL = 1e-9
"""Relative tolerance for values the contract defines as copies (force = drive-force column)."""


def channel_table_dtype() -> np.dtype:
    """Numpy dtype of the ``/setup/channels`` compound table (strings variable-length UTF-8)."""
    fields: list[tuple[str, Any]] = []
    for name in CHANNEL_FIELDS:
        if name in _STRING_FIELDS:
            fields.append((name, h5py.string_dtype()))
        elif name == "point":
            fields.append((name, np.int64))
        else:
            fields.append((name, np.float64))
    return np.dtype(fields)


def is_string_field(name: str) -> bool:
    """True if channel-table field ``name`` holds a string."""
    return name in _STRING_FIELDS


# -- errors ------------------------------------------------------------------------------------
class MeasurementFileError(ValueError):
    """A measurement file (or data meant for one) does not follow the contract.

    Parameters
    ----------
    file : str or path-like
        The file on disk.
    location : str
        Path of the object inside the file, e.g. ``"/steps/force"``.
    expected, found : str
        What the contract asks for and what is there.
    attribute : str, optional
        Name of the attribute of ``location`` concerned, if any.
    """

    def __init__(
        self, file: Any, location: str, expected: str, found: str, attribute: str | None = None
    ) -> None:
        self.file = str(file)
        self.location = location
        self.expected = expected
        self.found = found
        self.attribute = attribute
        where = location if attribute is None else f"{location} (attribute {attribute!r})"
        super().__init__(f"{self.file}: {where}: expected {expected}; found {found}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (
            type(self),
            (self.file, self.location, self.expected, self.found, self.attribute),
        )


class FieldValueError(ValueError):
    """A field of a record has a wrong type, shape or value.

    Raised when a record is constructed (``ChannelInfo``, ``StepRecord``, ...); the reader turns
    it into a :class:`MeasurementFileError` that names the place in the file.

    Parameters
    ----------
    owner : str
        What the field belongs to, e.g. ``"StepRecord"`` or ``"ChannelInfo 'acc7'"``.
    field : str
        Name of the field.
    expected, found : str
        What is required and what was given.
    """

    def __init__(self, owner: str, field: str, expected: str, found: str) -> None:
        self.owner = owner
        self.field = field
        self.expected = expected
        self.found = found
        super().__init__(f"{owner}.{field}: expected {expected}; found {found}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.owner, self.field, self.expected, self.found))


# -- array specification and checks ------------------------------------------------------------
_DTYPES: dict[str, np.dtype] = {
    "int64": np.dtype(np.int64),
    "int8": np.dtype(np.int8),
    "float64": np.dtype(np.float64),
    "complex128": np.dtype(np.complex128),
    "bool": np.dtype(np.bool_),
}

_CHECKS = {
    "": "",
    "positive": "> 0",
    "nonnegative": ">= 0",
    "at-least-one": ">= 1",
    "plus-minus-one": "+1 or -1",
    "unit-interval": "within [0, 1]",
    "increasing": "strictly increasing",
}


@dataclass(frozen=True)
class ArraySpec:
    """How one array of the contract is stored.

    Attributes
    ----------
    name : str
        Dataset name in the file.
    dtype : str
        One of ``"int64"``, ``"int8"``, ``"float64"``, ``"complex128"``, ``"bool"``.
    dims : tuple of str
        Symbolic shape after the step axis (``"C"`` channels, ``"H"`` orders).
    unit : str
        Unit for documentation ("" for channel units or counts).
    check : str
        Value constraint, a key of the internal check table ("" for none).
    field : str
        Attribute name on :class:`StepRecord` and :class:`SteppedSineData` (defaults to ``name``).
    """

    name: str
    dtype: str
    dims: tuple[str, ...]
    unit: str
    check: str = ""
    field: str = ""

    def __post_init__(self) -> None:
        if self.dtype not in _DTYPES:
            raise ValueError(f"ArraySpec {self.name!r}: unknown dtype {self.dtype!r}")
        if self.check not in _CHECKS:
            raise ValueError(f"ArraySpec {self.name!r}: unknown check {self.check!r}")
        if not self.field:
            object.__setattr__(self, "field", self.name)


STEP_FIELDS: tuple[ArraySpec, ...] = (
    ArraySpec("plan_index", "int64", (), "", "nonnegative"),
    ArraySpec("level_index", "int64", (), "", "nonnegative"),
    ArraySpec("sweep_direction", "int8", (), "", "plus-minus-one"),
    ArraySpec("frequency_target", "float64", (), "Hz", "positive", "frequency_target_hz"),
    ArraySpec("frequency", "float64", (), "Hz", "positive", "frequency_hz"),
    ArraySpec("force", "complex128", ("H",), "N"),
    ArraySpec("force_std", "float64", ("H",), "N", "nonnegative"),
    ArraySpec("response", "complex128", ("C", "H"), ""),
    ArraySpec("response_std", "float64", ("C", "H"), "", "nonnegative"),
    ArraySpec("drive", "complex128", ("H",), "V"),
    ArraySpec("n_blocks", "int64", (), "", "at-least-one"),
    ArraySpec("control_iterations", "int64", (), "", "nonnegative"),
    ArraySpec("control_converged", "bool", (), ""),
    ArraySpec("control_error", "float64", (), "", "nonnegative"),
    ArraySpec("timestamp", "float64", (), "s"),
)
"""The datasets of ``/steps`` in contract order (each has a leading step axis)."""

EXTRA_FORCE_FIELDS: tuple[ArraySpec, ...] = (
    ArraySpec("extra_force", "complex128", ("E",), "N"),
    ArraySpec("extra_force_std", "float64", ("E",), "N", "nonnegative"),
)
"""The optional datasets of ``/steps`` with the drive force at the extra orders
(``/extra_orders_num``, ``/extra_orders_den``): orders the drive does not contain at which the
force gauge still measures a force (present exactly when the file has extra orders)."""


def step_fields(n_extra: int) -> tuple[ArraySpec, ...]:
    """The ``/steps`` datasets of a file with ``n_extra`` extra orders."""
    return STEP_FIELDS + (EXTRA_FORCE_FIELDS if n_extra else ())


def _describe_dtype(dtype: np.dtype) -> str:
    if dtype.names:
        inner = ", ".join(f"{n} {dtype.fields[n][0]}" for n in dtype.names)
        return f"compound ({inner})"
    if h5py.check_string_dtype(dtype) is not None or dtype.kind in "SUO":
        return f"strings ({dtype})"
    return str(dtype)


def _shape_text(shape: tuple[int | None, ...]) -> str:
    dims = ", ".join("any" if s is None else str(s) for s in shape)
    return f"({dims},)" if len(shape) == 1 else f"({dims})"


def _coerce_dtype(arr: np.ndarray, dtype: str) -> np.ndarray | None:
    """Cast ``arr`` to the contract dtype if that is a same-kind cast, else return None."""
    target = _DTYPES[dtype]
    kind = arr.dtype.kind
    if dtype == "bool":
        if kind == "b" or (kind in "iu" and np.all((arr == 0) | (arr == 1))):
            return arr.astype(np.bool_)
        return None
    if kind == "b" or arr.dtype.names or kind not in "iufc":
        return None
    if not np.can_cast(arr.dtype, target, casting="same_kind"):
        return None
    if dtype == "int8" and arr.size and (arr.min() < -128 or arr.max() > 127):
        return None
    return arr.astype(target)


def _first_bad(mask: np.ndarray, arr: np.ndarray) -> str:
    idx = tuple(int(i) for i in np.argwhere(mask)[0])
    value = arr[idx].item()
    return f"{value!r} at index {idx}" if arr.ndim else repr(value)


def _value_problem(arr: np.ndarray, check: str) -> tuple[str, str] | None:
    """Return (requirement, first offending value) if ``arr`` breaks ``check``, else None."""
    if arr.dtype.kind in "fc":
        bad = ~np.isfinite(arr)
        if bad.any():
            return "finite values", _first_bad(bad, arr)
    if not check or not arr.size:
        return None
    if check == "positive":
        bad = ~(arr > 0)
    elif check == "nonnegative":
        bad = ~(arr >= 0)
    elif check == "at-least-one":
        bad = ~(arr >= 1)
    elif check == "plus-minus-one":
        bad = ~((arr == 1) | (arr == -1))
    elif check == "unit-interval":
        bad = ~((arr >= 0) & (arr <= 1 + 1e-9))
    else:  # increasing
        bad = np.zeros(arr.shape, dtype=bool)
        bad[1:] = ~(np.diff(arr) > 0)
    if bad.any():
        return f"values {_CHECKS[check]}", _first_bad(bad, arr)
    return None


def check_array(
    value: Any,
    *,
    dtype: str,
    shape: tuple[int | None, ...],
    check: str = "",
    owner: str,
    field: str,
) -> np.ndarray:
    """Validate an array against the contract and return it as a read-only contract-typed copy.

    Parameters
    ----------
    value : array_like
        The data.
    dtype : str
        Contract dtype (``"int64"``, ``"int8"``, ``"float64"``, ``"complex128"``, ``"bool"``).
        Any same-kind numeric input is accepted (e.g. float32 for float64, int32 for int64,
        real for complex); integers 0/1 are accepted for bool.
    shape : tuple of int or None
        Required shape; ``None`` matches any length along that axis.
    check : str
        Value constraint: ``""``, ``"positive"``, ``"nonnegative"``, ``"at-least-one"``,
        ``"plus-minus-one"``, ``"unit-interval"``, ``"increasing"``. Floating-point and complex
        values must always be finite.
    owner, field : str
        Names used in the error message.

    Returns
    -------
    ndarray
        A read-only copy of ``value`` with the contract dtype.

    Raises
    ------
    FieldValueError
        Naming ``owner.field``, what was expected and what was found.
    """
    expect = f"{dtype} array of shape {_shape_text(shape)}" if shape else f"{dtype} scalar"
    arr = np.array(value, copy=True)
    out = _coerce_dtype(arr, dtype)
    if out is None:
        raise FieldValueError(owner, field, expect, _describe_dtype(arr.dtype))
    if out.ndim != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, out.shape, strict=True)
    ):
        raise FieldValueError(owner, field, expect, f"shape {out.shape}")
    problem = _value_problem(out, check)
    if problem is not None:
        raise FieldValueError(owner, field, *problem)
    out.flags.writeable = False
    return out


def is_copy(a: np.ndarray, b: np.ndarray) -> bool:
    """True if ``a`` equals ``b`` up to rounding (the contract's "copy of that column")."""
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=_COPY_RTOL, atol=0.0))


def check_text(value: Any, *, owner: str, field: str, allowed: tuple[str, ...] = ()) -> str:
    """Validate a string field (optionally one of ``allowed``) and return it."""
    if not isinstance(value, str):
        raise FieldValueError(owner, field, "a string", f"{type(value).__name__} {value!r}")
    if allowed and value not in allowed:
        raise FieldValueError(owner, field, f"one of {', '.join(allowed)}", repr(value))
    return value


def check_int(value: Any, *, owner: str, field: str, minimum: int | None = None) -> int:
    """Validate an integer (Python or numpy, not bool) and return it as ``int``."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise FieldValueError(owner, field, "an integer", f"{type(value).__name__} {value!r}")
    if minimum is not None and value < minimum:
        raise FieldValueError(owner, field, f"an integer >= {minimum}", repr(int(value)))
    return int(value)


def check_float(
    value: Any,
    *,
    owner: str,
    field: str,
    minimum: float | None = None,
    positive: bool = False,
    below: float | None = None,
) -> float:
    """Validate a finite real number and return it as ``float``.

    ``minimum`` is inclusive, ``positive`` requires > 0, ``below`` is an exclusive upper bound.
    """
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
        raise FieldValueError(owner, field, "a real number", f"{type(value).__name__} {value!r}")
    if isinstance(value, complex | np.complexfloating):
        raise FieldValueError(owner, field, "a real number", f"complex {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise FieldValueError(owner, field, "a finite number", repr(x))
    if positive and not x > 0:
        raise FieldValueError(owner, field, "a number > 0", repr(x))
    if minimum is not None and x < minimum:
        raise FieldValueError(owner, field, f"a number >= {minimum:g}", repr(x))
    if below is not None and not x < below:
        raise FieldValueError(owner, field, f"a number < {below:g}", repr(x))
    return x


def safe_std(std: Any, floor: Any) -> np.ndarray:
    """Standard errors with a lower bound, safe to divide by.

    The contract allows a stored standard error of 0 (a value known exactly, e.g. in a
    synthetic file); weighting by ``1 / std`` must therefore go through this guard.

    Parameters
    ----------
    std : array_like, any shape
        Standard errors (``force_std``, ``response_std``), in the unit of the phasor.
    floor : float or array_like broadcastable to ``std``
        Smallest standard error to use, > 0, same unit; e.g. a fraction of the phasor
        magnitude or the noise floor of the channel.

    Returns
    -------
    ndarray
        ``max(std, floor)`` elementwise, float64.
    """
    std = np.asarray(std, dtype=float)
    floor = np.asarray(floor, dtype=float)
    if not np.all(np.isfinite(floor)) or not np.all(floor > 0):
        raise ValueError("safe_std: floor must be finite and > 0")
    if np.any(std < 0) or not np.all(np.isfinite(std)):
        raise ValueError("safe_std: std must be finite and >= 0")
    return np.maximum(std, floor)
