"""Primitives for validating an open HDF5 file: each violation becomes a MeasurementFileError.

:class:`FileChecker` fetches groups, datasets and attributes by their path in the file and
raises :class:`~analysis.measurement_file.schema.MeasurementFileError` naming the file, that
path (and attribute), what was expected and what was found.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NoReturn

import h5py
import numpy as np

from .schema import FieldValueError, MeasurementFileError

__all__ = ["FileChecker", "as_text", "open_file"]


@contextmanager
def open_file(path: Path, mode: str = "r") -> Iterator[h5py.File]:
    """Open an existing file as HDF5; a non-HDF5 file raises :class:`MeasurementFileError`."""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such measurement file")
    try:
        f = h5py.File(path, mode)
    except OSError as exc:
        raise MeasurementFileError(path, "/", "an HDF5 file", f"unreadable ({exc})") from exc
    with f:
        yield f


def as_text(value: Any) -> str | None:
    """A string attribute or field value as ``str`` (None if it is not a string)."""
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(()).item()
    if isinstance(value, bytes | np.bytes_):
        try:
            return bytes(value).decode("utf-8")
        except UnicodeDecodeError:
            return None
    return value if isinstance(value, str) else None


class FileChecker:
    """Reads one open file, turning every violation into a :class:`MeasurementFileError`.

    Parameters
    ----------
    f : h5py.File
        The open file.
    path : Path
        Its path on disk (for messages).
    """

    def __init__(self, f: h5py.File, path: Path) -> None:
        self.f = f
        self.path = path

    def fail(
        self, location: str, expected: str, found: str, attribute: str | None = None
    ) -> NoReturn:
        """Raise the :class:`MeasurementFileError` for a violation at ``location``."""
        raise MeasurementFileError(self.path, location, expected, found, attribute)

    @contextmanager
    def at(self, location: str, attribute: str | None = None) -> Iterator[None]:
        """Report a :class:`FieldValueError` raised inside as a violation at ``location``."""
        try:
            yield
        except FieldValueError as exc:
            self.fail(location, exc.expected, exc.found, attribute)

    def group(self, location: str) -> h5py.Group:
        """The group at ``location``."""
        obj = self.f.get(location)
        if not isinstance(obj, h5py.Group):
            self.fail(location, "a group", "nothing" if obj is None else "a dataset")
        return obj

    def dataset(self, location: str) -> h5py.Dataset:
        """The dataset at ``location``."""
        obj = self.f.get(location)
        if not isinstance(obj, h5py.Dataset):
            self.fail(location, "a dataset", "nothing" if obj is None else "a group")
        return obj

    def read(self, location: str, dtype: str, rows: int | None = None) -> np.ndarray:
        """Read a dataset (its first ``rows`` rows); a complex one must be stored as complex."""
        ds = self.dataset(location)
        if dtype == "complex128" and ds.dtype.kind != "c":
            self.fail(location, "complex128 values (HDF5 compound of float64 r, i)", f"{ds.dtype}")
        try:
            return ds[()] if rows is None else ds[:rows]
        except (OSError, TypeError, ValueError) as exc:
            self.fail(location, "readable data", f"unreadable ({exc})")

    def attr(self, obj: h5py.HLObject, name: str) -> Any:
        """Attribute ``name`` of ``obj`` (a one-element array is unwrapped)."""
        if name not in obj.attrs:
            self.fail(obj.name, "this attribute", "no such attribute", name)
        try:
            value = obj.attrs[name]
        except (OSError, TypeError, ValueError) as exc:
            self.fail(obj.name, "a readable attribute", f"unreadable ({exc})", name)
        if isinstance(value, np.ndarray) and value.size == 1:
            value = value.reshape(()).item()
        return value

    def attr_text(self, obj: h5py.HLObject, name: str, allowed: tuple[str, ...] = ()) -> str:
        """A string attribute, optionally one of ``allowed``."""
        value = self.attr(obj, name)
        text = as_text(value)
        if text is None:
            self.fail(obj.name, "a UTF-8 string", f"{type(value).__name__} {value!r}", name)
        if allowed and text not in allowed:
            self.fail(obj.name, f"one of {', '.join(allowed)}", repr(text), name)
        return text

    def attr_int(self, obj: h5py.HLObject, name: str, minimum: int | None = 0) -> int:
        """An integer attribute >= ``minimum`` (an integer-valued float is accepted)."""
        value = self.attr(obj, name)
        if isinstance(value, float | np.floating) and float(value).is_integer():
            value = int(value)
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
            self.fail(obj.name, "an integer", f"{type(value).__name__} {value!r}", name)
        if minimum is not None and value < minimum:
            self.fail(obj.name, f"an integer >= {minimum}", repr(int(value)), name)
        return int(value)

    def attr_bool(self, obj: h5py.HLObject, name: str) -> bool:
        """A boolean attribute (integer 0/1 accepted)."""
        value = self.attr(obj, name)
        if isinstance(value, bool | np.bool_) or (
            isinstance(value, int | np.integer) and value in (0, 1)
        ):
            return bool(value)
        return self.fail(obj.name, "a boolean", f"{type(value).__name__} {value!r}", name)

    def attr_json(self, obj: h5py.HLObject, name: str) -> dict[str, Any]:
        """A string attribute holding a JSON object, parsed."""
        text = self.attr_text(obj, name)
        try:
            value = json.loads(text)
        except json.JSONDecodeError as exc:
            self.fail(obj.name, "a JSON object", f"invalid JSON ({exc})", name)
        if not isinstance(value, dict):
            self.fail(obj.name, "a JSON object", f"JSON {type(value).__name__}", name)
        return value
