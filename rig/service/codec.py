"""Events as JSON: one encoder for the frozen dataclasses of :mod:`rig.run.events`, and the decoder
clients use to turn the stream back into them (:func:`decode_event`).

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
from types import SimpleNamespace
from typing import Any

import numpy as np

from rig.config.plans import PlannedStep
from rig.procedures.pretest import ChannelCheck, PretestReport
from rig.run.events import (
    ControlIteration,
    Event,
    FaultRaised,
    PretestFinished,
    RecordAcquired,
    RunFinished,
    RunPaused,
    RunResumed,
    RunStarted,
    RunWarning,
    StepFinished,
    StepStarted,
)

__all__ = ["decode_event", "encode_event", "event_line", "to_jsonable"]


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


def _scalar(obj: np.generic) -> Any:
    """A NumPy scalar as the Python number (or value) it holds."""
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.complexfloating):
        return to_jsonable(complex(obj))
    if isinstance(obj, np.floating):
        return _number(float(obj))
    return to_jsonable(obj.item())


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
        return _scalar(obj)
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
    """The stream's object for an event of :mod:`rig.run.events` (or any frozen dataclass with a
    ``time_s`` field).

    Parameters
    ----------
    event : rig.run.events.Event
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


# -- decoding (clients) ----------------------------------------------------------------------
_COMPLEX = ("force", "response", "drive", "drive_v", "force_n", "gain_n_per_v")
_REAL = ("force_std", "response_std", "force_std_n")


def _float(x: Any) -> float:
    return math.nan if x is None else float(x)


def _complex(x: Any) -> np.ndarray:
    """Nested lists ending in ``[re, im]`` pairs -> complex array (``null`` -> NaN)."""
    a = np.array(x, dtype=float)
    return a[..., 0] + 1j * a[..., 1]


def _fields(d: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        if k in _COMPLEX and v is not None:
            out[k] = _complex(v)
        elif k in _REAL and v is not None:
            out[k] = np.array(v, dtype=float)
        else:
            out[k] = v
    return out


def _pretest(d: dict[str, Any]) -> PretestReport:
    channels = tuple(
        ChannelCheck(
            c["name"],
            int(c["point"]),
            c["status"],
            _float(c["noise_rms"]),
            _float(c["response"]),
            _float(c["snr"]),
            c.get("message", ""),
        )
        for c in d.get("channels", [])
    )
    gain = d.get("gain_n_per_v")
    return PretestReport(
        _float(d.get("frequency_hz")),
        channels,
        _complex(d["drive_v"]) if d.get("drive_v") else np.zeros(0, complex),
        _complex(d["force_n"]) if d.get("force_n") else np.zeros(0, complex),
        None if gain is None else _complex(gain),
    )


def decode_event(obj: dict[str, Any]) -> Event | None:
    """The :mod:`rig.run.events` object of one event of the stream (None for the service's own
    ``RunState`` and for types this GUI does not draw)."""
    kind, d = obj.get("type"), obj.get("data", {})
    t = {"time_s": _float(obj.get("time_s"))}
    if kind == "RunStarted":
        return RunStarted(d["plan_name"], d["kind"], d["n_steps"], d["n_done"], d["path"], **t)
    if kind == "PretestFinished":
        return PretestFinished(_pretest(d["report"]), **t)
    if kind == "StepStarted":
        return StepStarted(PlannedStep(**d["step"]), d["n_steps"], **t)
    if kind == "ControlIteration":
        f = _fields(d)
        return ControlIteration(
            f["plan_index"],
            f["iteration"],
            f["status"],
            f["accepted"],
            _float(f["error"]),
            _float(f["frequency_hz"]),
            f["drive_v"],
            f["force_n"],
            f["force_std_n"],
            **t,
        )
    if kind == "StepFinished":
        record = SimpleNamespace(**_fields(d["record"]))
        record.control_error = _float(record.control_error)
        names = tuple(d["channel_names"])
        return StepFinished(record, None, names, d["n_done"], d["n_steps"], d["settled"], **t)
    if kind == "RecordAcquired":
        return RecordAcquired(d["index"], d["n_records"], d["purpose"], **t)
    if kind == "RunWarning":
        return RunWarning(d["kind"], d["message"], d.get("channel", ""), **t)
    if kind == "FaultRaised":
        return FaultRaised(
            d["kind"], d["message"], d.get("channel", ""), bool(d.get("paused")), **t
        )
    if kind == "RunPaused":
        return RunPaused(d.get("reason", ""), **t)
    if kind == "RunResumed":
        return RunResumed(**t)
    if kind == "RunFinished":
        return RunFinished(d["status"], d.get("message", ""), **t)
    return None
