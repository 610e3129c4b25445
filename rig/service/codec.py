"""Events as JSON: one encoder for the frozen dataclasses of :mod:`rig.events`.

An event becomes ``{"seq", "run", "type", "time_s", "data"}``: ``type`` is its class name,
``data`` its other fields, converted recursively:

- dataclasses (a step record, the controller's record, a planned step, the pretest report)
  become objects of their fields;
- complex numbers become ``[re, im]`` pairs, complex arrays nested lists ending in such pairs
  (shape ``(..., 2)``); real arrays nested lists; numpy scalars plain numbers;
- NaN and infinities become ``null`` (strict JSON has no NaN);
- fractions (harmonic orders such as ``1/2``) become strings; paths strings; mappings objects
  with string keys; anything else its ``str()``.

The result is plain data: it is never unpickled or evaluated on either side.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Mapping
from fractions import Fraction
from os import PathLike
from typing import Any

import numpy as np

__all__ = ["encode_event", "event_line", "to_jsonable"]


def _number(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _array(a: np.ndarray) -> Any:
    if a.dtype == object:
        return [to_jsonable(v) for v in a.tolist()]
    if np.iscomplexobj(a):
        a = np.stack([a.real, a.imag], axis=-1)
    if a.dtype.kind == "f":
        finite = np.isfinite(a)
        if not finite.all():
            out = a.astype(object)
            out[~finite] = None
            return out.tolist()
    if a.dtype.kind in "fiub":
        return a.tolist()
    return [to_jsonable(v) for v in a.tolist()]


def to_jsonable(obj: Any) -> Any:
    """Plain JSON data (dicts, lists, str, numbers, bools, None) for ``obj``."""
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return _number(obj)
    if isinstance(obj, complex):
        return [_number(obj.real), _number(obj.imag)]
    if isinstance(obj, np.ndarray):
        return _array(obj)
    if isinstance(obj, np.generic):
        if isinstance(obj, np.bool_):
            return bool(obj)
        if isinstance(obj, np.integer):
            return int(obj)
        if isinstance(obj, np.complexfloating):
            return to_jsonable(complex(obj))
        if isinstance(obj, np.floating):
            return _number(float(obj))
        return to_jsonable(obj.item())
    if isinstance(obj, Fraction):
        return str(obj)
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, PathLike):
        return str(obj)
    return str(obj)


def encode_event(event: Any, run_id: str, seq: int) -> dict[str, Any]:
    """The stream's object for an event of :mod:`rig.events` (or any frozen dataclass with a
    ``time_s`` field).

    Parameters
    ----------
    event : rig.events.Event
    run_id : str
        The run it belongs to.
    seq : int
        Its number in the run's stream (1, 2, ... without gaps).
    """
    data = {
        f.name: to_jsonable(getattr(event, f.name))
        for f in dataclasses.fields(event)
        if f.name != "time_s"
    }
    return {
        "seq": int(seq),
        "run": run_id,
        "type": type(event).__name__,
        "time_s": _number(float(getattr(event, "time_s", math.nan))),
        "data": data,
    }


def event_line(obj: Mapping[str, Any]) -> bytes:
    """One line of the event stream: compact strict JSON and a newline."""
    return (json.dumps(obj, separators=(",", ":"), allow_nan=False) + "\n").encode("utf-8")
