"""Read and validate measurement files (any writer: the rig, the simulator, third parties).

Everything the contract requires is checked; the first violation raises
:class:`~analysis.measurement_file.schema.MeasurementFileError` with the file, the path inside
it, what was expected and what was found. What the contract leaves open is read leniently:

- numeric datasets of the same kind but another width (int32 for int64, float32 for float64,
  complex64 for complex128), integers for floats and integer 0/1 for bool are accepted and
  converted; complex data must be stored as complex (a real array has lost its phase);
- strings may also be fixed-length bytes (UTF-8) and attributes one-element arrays, as some
  HDF5 tools write them;
- extra attributes, datasets and channel-table fields are ignored (compatible extensions);
- datasets need not be chunked or resizable; rows of ``/steps`` beyond ``n_complete`` (a step
  in progress when a run died) are ignored.

Versions: format_version 2 is the newest this module knows; a newer file is refused with a
message saying so (its changes cannot be interpreted). Version 2 adds the root attributes
``output_at_zero`` (bool) and ``resumes`` (a JSON array of resume events); a version-1 file,
which has neither, reads with ``output_at_zero`` None and no resumes. When the format grows,
the loader of every older version stays here, so older files keep reading.
"""

from __future__ import annotations

import json
import logging
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .data import RandomData, RawRecord, ResumeEvent, SteppedSineData
from .h5check import FileChecker, as_text, open_file
from .records import (
    ESTIMATORS,
    Actuator,
    ChannelInfo,
    RandomFRF,
    check_channels,
    check_extra_orders,
    check_plan,
    drive_force_index,
)
from .schema import (
    CHANNEL_FIELDS,
    EXIT_STATUSES,
    FORMAT,
    FORMAT_VERSION,
    KIND_STEPPED_SINE,
    KINDS,
    FieldValueError,
    check_array,
    check_float,
    is_copy,
    is_string_field,
    step_fields,
)

__all__ = ["load_open_file", "read_measurement", "read_raw"]

_RESUME_FIELDS = {
    "time": str,
    "steps_on_disk": int,
    "next_plan_index": int,
    "previous_status": str,
    "previous_message": str,
}

log = logging.getLogger(__name__)

_FRF_PLACES = {
    "frequency_hz": ("/frf/frequency", None),
    "h1": ("/frf/h1", None),
    "coherence": ("/frf/coherence", None),
    "force_psd": ("/frf/force_psd", None),
    "n_averages": ("/frf", "n_averages"),
    "window": ("/frf", "window"),
    "overlap": ("/frf", "overlap"),
    "fs_hz": ("/frf", "fs"),
    "rms_force_n": ("/frf", "rms_force_n"),
}


def read_measurement(path: str | PathLike[str]) -> SteppedSineData | RandomData:
    """Read and validate a measurement file.

    Parameters
    ----------
    path : str or path-like
        The HDF5 file.

    Returns
    -------
    SteppedSineData or RandomData
        By the root attribute ``kind``. For a stepped-sine file only the first ``n_complete``
        steps are returned.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    MeasurementFileError
        If the file does not follow the contract (message: file, path inside it, expected,
        found).
    """
    path = Path(path)
    with open_file(path) as f:
        return load_open_file(f, path)


def read_raw(path: str | PathLike[str], plan_index: int) -> RawRecord:
    """Read the raw time data of one step (``/raw/<plan_index>``).

    Raises
    ------
    KeyError
        If the file holds no raw data for ``plan_index``.
    MeasurementFileError
        If the file or the raw dataset does not follow the contract.
    """
    path = Path(path)
    with open_file(path) as f:
        chk = _Checker(f, path)
        chk.header()
        n_channels = len(chk.channels())
        loc = f"/raw/{int(plan_index)}"
        if loc not in f:
            raise KeyError(f"{path}: no raw data for plan_index {plan_index} ({loc})")
        ds, fs_hz, t0_s = chk.raw_dataset(loc, n_channels)
        return RawRecord(int(plan_index), ds[()].astype(np.float32), fs_hz, t0_s)


def load_open_file(f: h5py.File, path: Path) -> SteppedSineData | RandomData:
    """Validate and load an open HDF5 file (see :func:`read_measurement`)."""
    chk = _Checker(f, path)
    common = chk.header()
    common["channels"] = chk.channels()
    common["actuator"] = chk.actuator()
    if common.pop("kind") == KIND_STEPPED_SINE:
        return SteppedSineData(**common, **chk.stepped_sine(common["channels"]))
    return RandomData(**common, **chk.random(common["channels"]))


class _Checker(FileChecker):
    """Validates and loads the parts of one open measurement file."""

    # -- common parts -------------------------------------------------------------------------
    def header(self) -> dict[str, Any]:
        """Validate the root attributes and ``/setup``; return the common fields and ``kind``."""
        f = self.f
        fmt = self.attr_text(f, "format")
        if fmt != FORMAT:
            self.fail("/", repr(FORMAT), repr(fmt), "format")
        version = self.attr_int(f, "format_version", minimum=None)
        if version > FORMAT_VERSION:
            self.fail(
                "/",
                f"format_version at most {FORMAT_VERSION} (the newest this reader knows)",
                f"{version}: the file uses a newer layout whose changes this reader cannot "
                f"interpret; read it with a clearance-rig that supports format_version {version}",
                "format_version",
            )
        if version < 1:
            self.fail(
                "/", "format_version >= 1 (1 is the first version)", str(version), "format_version"
            )
        kind = self.attr_text(f, "kind", KINDS)
        created_text = self.attr_text(f, "created")
        try:
            created = datetime.fromisoformat(created_text)
        except ValueError:
            self.fail("/", "an ISO 8601 UTC time", repr(created_text), "created")
        created = created.replace(tzinfo=UTC) if created.tzinfo is None else created.astimezone(UTC)
        software = {str(k): str(v) for k, v in self.attr_json(f, "software").items()}
        complete = self.attr_bool(f, "complete")
        status = self.attr_text(f, "exit_status", EXIT_STATUSES)
        message = self.attr_text(f, "exit_message")
        if complete != (status == "success"):
            self.fail(
                "/",
                "complete true exactly when exit_status is 'success'",
                f"complete {complete} with exit_status {status!r}",
                "complete",
            )
        output_at_zero = None
        resumes: tuple[ResumeEvent, ...] = ()
        if version >= 2:
            output_at_zero = self.attr_bool(f, "output_at_zero")
            resumes = self.resumes()
        setup = self.group("/setup")
        return {
            "path": self.path,
            "format_version": version,
            "kind": kind,
            "complete": complete,
            "exit_status": status,
            "exit_message": message,
            "created": created,
            "software": software,
            "config": self.attr_json(setup, "config_json"),
            "setup": self.attr_json(setup, "setup_json"),
            "output_at_zero": output_at_zero,
            "resumes": resumes,
        }

    def resumes(self) -> tuple[ResumeEvent, ...]:
        """The root attribute ``resumes``: a JSON array of resume events."""
        text = self.attr_text(self.f, "resumes")
        want = (
            "a JSON array of objects with time (str), steps_on_disk (int >= 0), next_plan_index "
            "(int >= 0), previous_status (str), previous_message (str)"
        )
        try:
            items = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as exc:
            self.fail("/", want, f"invalid JSON ({exc})", "resumes")
        if not isinstance(items, list):
            self.fail("/", want, f"a JSON {type(items).__name__}", "resumes")
        events = []
        for i, item in enumerate(items):
            ok = isinstance(item, dict) and set(item) >= set(_RESUME_FIELDS)
            if ok:
                values = {k: item[k] for k in _RESUME_FIELDS}
                for k, kind in _RESUME_FIELDS.items():
                    v = values[k]
                    if kind is int:
                        ok = ok and type(v) is int and v >= 0
                    else:
                        ok = ok and isinstance(v, str)
            if not ok:
                self.fail("/", want, f"entry {i}: {item!r:.200}", "resumes")
            events.append(ResumeEvent(**values))
        return tuple(events)

    def channels(self) -> tuple[ChannelInfo, ...]:
        loc = "/setup/channels"
        ds = self.dataset(loc)
        names = ds.dtype.names or ()
        missing = [n for n in CHANNEL_FIELDS if n not in names]
        if missing:
            self.fail(
                loc,
                f"a compound table with fields {', '.join(CHANNEL_FIELDS)}",
                f"fields {list(names)} (missing {missing})",
            )
        if ds.ndim != 1 or ds.shape[0] == 0:
            self.fail(loc, "a 1-D table with one row per channel", f"shape {ds.shape}")
        for name in CHANNEL_FIELDS:
            sub = ds.dtype.fields[name][0]
            text = h5py.check_string_dtype(sub) is not None or sub.kind == "S"
            kinds = "iu" if name == "point" else "iuf"
            if (is_string_field(name) and not text) or (
                not is_string_field(name) and sub.kind not in kinds
            ):
                want = "string" if is_string_field(name) else "integer" if kinds == "iu" else "real"
                self.fail(loc, f"field {name!r} of {want} type", f"type {sub}")
        rows = ds[()]
        chans = []
        for i, row in enumerate(rows):
            values: dict[str, Any] = {}
            for name in CHANNEL_FIELDS:
                value = row[name]
                if is_string_field(name):
                    value = as_text(value)
                    if value is None:
                        self.fail(loc, f"row {i}, field {name!r}: UTF-8 text", repr(row[name]))
                values[name] = value.item() if isinstance(value, np.generic) else value
            try:
                chans.append(ChannelInfo(**values))
            except FieldValueError as exc:
                self.fail(loc, f"row {i}, field {exc.field!r}: {exc.expected}", exc.found)
        with self.at(loc):
            return check_channels(chans)

    def actuator(self) -> Actuator:
        act = self.group("/setup/actuator")
        point = self.attr_int(act, "point")
        direction = self.attr_text(act, "direction")
        static = 0.0
        if "static_stiffness_n_per_m" in act.attrs:
            static = self.attr(act, "static_stiffness_n_per_m")
        try:
            return Actuator(point, direction, static)
        except FieldValueError as exc:
            self.fail(act.name, exc.expected, exc.found, exc.field)

    # -- stepped sine -------------------------------------------------------------------------
    def stepped_sine(self, channels: tuple[ChannelInfo, ...]) -> dict[str, Any]:
        raw_plan = {
            n: self.read(f"/{n}", "complex128" if n == "force_targets" else "")
            for n in ("levels", "orders_num", "orders_den", "force_targets")
        }
        try:
            levels, num, den, targets = check_plan(*raw_plan.values())
        except FieldValueError as exc:
            self.fail(f"/{exc.field}", exc.expected, exc.found)
        extra = [f"/{n}" for n in ("extra_orders_num", "extra_orders_den")]
        present = [loc in self.f for loc in extra]
        if any(present) and not all(present):
            have, missing = (extra[0], extra[1]) if present[0] else (extra[1], extra[0])
            self.fail(missing, f"a dataset beside {have}", "none")
        extra_num = extra_den = np.zeros(0, np.int64)
        if all(present):
            try:
                extra_num, extra_den = check_extra_orders(
                    self.read(extra[0], ""), self.read(extra[1], ""), num, den
                )
            except FieldValueError as exc:
                self.fail(f"/{exc.field}", exc.expected, exc.found)
        out: dict[str, Any] = {
            "levels_n": levels,
            "orders_num": num,
            "orders_den": den,
            "force_targets": targets,
            "extra_orders_num": extra_num,
            "extra_orders_den": extra_den,
        }
        out.update(self.steps(len(channels), num.size, extra_num.size))
        n_levels = levels.size
        bad = np.flatnonzero(out["level_index"] >= n_levels)
        if bad.size:
            self.fail(
                "/steps/level_index",
                f"values < {n_levels} (the rows of /levels)",
                f"{out['level_index'][bad[0]]} at row {bad[0]}",
            )
        plans = out["plan_index"]
        uniq, counts = np.unique(plans, return_counts=True)
        if np.any(counts > 1):
            p = uniq[counts > 1][0]
            self.fail(
                "/steps/plan_index",
                "unique plan indices",
                f"{p} at rows {np.flatnonzero(plans == p).tolist()}",
            )
        d = drive_force_index(channels)
        for name, source in (("force", "response"), ("force_std", "response_std")):
            column = out[source][:, d, :]
            if not is_copy(out[name], column):
                differs = ~np.isclose(out[name], column, rtol=1e-9, atol=0)
                row = int(np.flatnonzero(differs.any(axis=1))[0])
                self.fail(
                    f"/steps/{name}",
                    f"a copy of the drive-force channel {channels[d].name!r} "
                    f"(/steps/{source}[:, {d}, :])",
                    f"{out[name][row].tolist()} vs {column[row].tolist()} at row {row}",
                )
        out["raw_plan_indices"] = self.raw_indices(len(channels), set(plans.tolist()))
        return out

    def steps(self, n_channels: int, n_orders: int, n_extra: int = 0) -> dict[str, np.ndarray]:
        steps = self.group("/steps")
        n = self.attr_int(steps, "n_complete")
        sizes = {"C": n_channels, "H": n_orders, "E": n_extra}
        out = {}
        for spec in step_fields(n_extra):
            loc = f"/steps/{spec.name}"
            ds = self.dataset(loc)
            dims = tuple(sizes[d] for d in spec.dims)
            if ds.ndim != 1 + len(dims) or ds.shape[1:] != dims:
                want = ", ".join(["n", *(f"{d}={sizes[d]}" for d in spec.dims)])
                self.fail(loc, f"shape ({want}{',' if not dims else ''})", f"shape {ds.shape}")
            if ds.shape[0] < n:
                self.fail(
                    "/steps", f"at most {ds.shape[0]} (the rows of {loc})", str(n), "n_complete"
                )
            with self.at(loc):
                out[spec.field] = check_array(
                    self.read(loc, spec.dtype, rows=n),
                    dtype=spec.dtype,
                    shape=(n, *dims),
                    check=spec.check,
                    owner=loc,
                    field=spec.name,
                )
        return out

    def raw_dataset(self, loc: str, n_channels: int) -> tuple[h5py.Dataset, float, float]:
        ds = self.dataset(loc)
        if ds.ndim != 2 or ds.shape[1] != n_channels:
            self.fail(loc, f"shape (n_samples, {n_channels})", f"shape {ds.shape}")
        if ds.dtype.kind != "f":
            self.fail(loc, "float32 samples", f"type {ds.dtype}")
        try:
            fs_hz = check_float(self.attr(ds, "fs"), owner=loc, field="fs", positive=True)
        except FieldValueError as exc:
            self.fail(loc, exc.expected, exc.found, "fs")
        try:
            t0_s = check_float(self.attr(ds, "t0"), owner=loc, field="t0")
        except FieldValueError as exc:
            self.fail(loc, exc.expected, exc.found, "t0")
        return ds, fs_hz, t0_s

    def raw_indices(self, n_channels: int, completed: set[int]) -> tuple[int, ...]:
        if "raw" not in self.f:
            return ()
        group = self.group("/raw")
        found = []
        for key in group:
            loc = f"/raw/{key}"
            if not key.isdigit():
                self.fail(loc, "a name that is a plan index (a decimal integer)", repr(key))
            if int(key) in completed:
                self.raw_dataset(loc, n_channels)
                found.append(int(key))
            else:  # possibly half written when the run died: not checked
                log.debug("%s: %s belongs to no completed step; ignored", self.path, loc)
        return tuple(sorted(found))

    # -- random -------------------------------------------------------------------------------
    def random(self, channels: tuple[ChannelInfo, ...]) -> dict[str, Any]:
        frf = self.group("/frf")
        estimator = self.attr_text(frf, "estimator")
        if estimator not in ESTIMATORS:
            self.fail("/frf", f"one of {ESTIMATORS}", repr(estimator), "estimator")
        freq = self.dataset("/frf/frequency")
        if freq.ndim != 1:
            self.fail(freq.name, "shape (nf,)", f"shape {freq.shape}")
        nf, nc = freq.shape[0], len(channels)
        shapes = {"h1": (nf, nc), "coherence": (nf, nc), "force_psd": (nf,)}
        values: dict[str, Any] = {}
        for field, (loc, attribute) in _FRF_PLACES.items():
            if attribute == "n_averages":
                values[field] = self.attr_int(frf, attribute, minimum=1)
                continue
            if attribute is not None:
                value = self.attr(frf, attribute)
                values[field] = as_text(value) if field == "window" else value
                continue
            want = shapes.get(field, (nf,))
            found = self.dataset(loc).shape
            if found != want:
                named = "(nf, C)" if len(want) == 2 else "(nf,)"
                self.fail(loc, f"shape {named} = {want}", f"shape {found}")
            values[field] = self.read(loc, "complex128" if field == "h1" else "")
        try:
            result = RandomFRF(**values, estimator=estimator)
            result.check_drive_force(drive_force_index(channels))
        except FieldValueError as exc:
            loc, attribute = _FRF_PLACES[exc.field]
            self.fail(loc, exc.expected, exc.found, attribute)
        return {
            "frequency_hz": result.frequency_hz,
            "h1": result.h1,
            "coherence": result.coherence,
            "force_psd": result.force_psd,
            "estimator": estimator,
            "n_averages": result.n_averages,
            "window": result.window,
            "overlap": result.overlap,
            "fs_hz": result.fs_hz,
            "rms_force_n": result.rms_force_n,
        }
