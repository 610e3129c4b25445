"""Write a stepped-sine measurement file step by step: crash-safe and resumable.

A stepped-sine file is written by one :class:`SteppedSineWriter` at a time (not thread-safe).
Each :meth:`SteppedSineWriter.append_step` writes every ``/steps`` dataset of the step, flushes,
and only then raises ``/steps`` attribute ``n_complete`` and flushes again, so a crash loses at
most the step in progress; readers ignore rows beyond ``n_complete``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from types import TracebackType
from typing import Any, NoReturn

import h5py
import numpy as np

from .data import RandomData, SteppedSineData
from .h5check import open_file
from .layout import build_file, software_versions, to_json, write_header
from .reader import load_open_file
from .records import (
    Actuator,
    ChannelInfo,
    StepRecord,
    check_channels,
    check_extra_orders,
    check_plan,
    drive_force_index,
)
from .schema import (
    FINAL_STATUSES,
    FORMAT_VERSION,
    KIND_STEPPED_SINE,
    ArraySpec,
    FieldValueError,
    MeasurementFileError,
    check_array,
    check_float,
    check_int,
    step_fields,
)

__all__ = [
    "SteppedSineWriter",
    "create_stepped_sine",
    "note_output_not_at_zero",
    "open_for_resume",
]

log = logging.getLogger(__name__)

_CHUNK_ROWS = 64


def create_stepped_sine(
    path: str | PathLike[str],
    *,
    channels: Iterable[ChannelInfo],
    actuator: Actuator,
    levels_n: Any,
    orders_num: Any,
    orders_den: Any,
    force_targets: Any,
    config: Mapping[str, Any],
    setup: Mapping[str, Any],
    raw: bool = False,
    software: Mapping[str, str] | None = None,
    overwrite: bool = False,
    extra_orders_num: Any = (),
    extra_orders_den: Any = (),
) -> SteppedSineWriter:
    """Create a stepped-sine measurement file and return its writer.

    The file appears complete in structure (``exit_status = "running"``, no steps) or not at
    all: it is built under a temporary name and renamed.

    Parameters
    ----------
    path : str or path-like
        The file to create.
    channels : iterable of ChannelInfo
        Acquired channels in acquisition order (``C``), exactly one of role ``"drive-force"``.
    actuator : Actuator
    levels_n : array_like, shape (L,), N
        Target fundamental force amplitudes.
    orders_num, orders_den : array_like of int, shape (H,)
        Orders as fractions of the fundamental, e.g. ``[1, 2, 3]`` and ``[1, 1, 1]``.
    force_targets : array_like, shape (L, H), complex, N
        Target force phasors.
    config, setup : mapping
        The full run configuration and the lab setup, stored as JSON (no NaN or infinity).
    raw : bool
        Create ``/raw`` so that :meth:`SteppedSineWriter.append_raw` can store time data.
    software : mapping of str to str, optional
        Extra package -> version entries for the ``software`` attribute.
    overwrite : bool
        Replace an existing file instead of refusing.
    extra_orders_num, extra_orders_den : array_like of int, shape (E,)
        Orders the drive does not contain at which every step also records the drive force
        (``StepRecord.extra_force``), e.g. the harmonics 4-8 of a drive with orders 1-3;
        empty (the default): none, and the file has no extra-order datasets.

    Returns
    -------
    SteppedSineWriter
        Open on the new file; use it as a context manager or call :meth:`~SteppedSineWriter.finish`.

    Raises
    ------
    FieldValueError
        If an argument is invalid (names the field).
    FileExistsError
        If ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    if not isinstance(actuator, Actuator):
        raise FieldValueError("create_stepped_sine", "actuator", "an Actuator", repr(actuator))
    chans = check_channels(channels)
    levels, num, den, targets = check_plan(levels_n, orders_num, orders_den, force_targets)
    extra_num, extra_den = check_extra_orders(extra_orders_num, extra_orders_den, num, den)
    config_json = to_json(config, "config")
    setup_json = to_json(setup, "setup")
    versions = software_versions(software)
    n_ch, n_ord = len(chans), num.size

    def fill(f: h5py.File) -> None:
        write_header(
            f,
            kind=KIND_STEPPED_SINE,
            channels=chans,
            actuator=actuator,
            config_json=config_json,
            setup_json=setup_json,
            software=versions,
            exit_status="running",
        )
        f.create_dataset("levels", data=levels)
        f.create_dataset("orders_num", data=num)
        f.create_dataset("orders_den", data=den)
        f.create_dataset("force_targets", data=targets)
        if extra_num.size:
            f.create_dataset("extra_orders_num", data=extra_num)
            f.create_dataset("extra_orders_den", data=extra_den)
        steps = f.create_group("steps")
        sizes = {"C": n_ch, "H": n_ord, "E": extra_num.size}
        for spec in step_fields(extra_num.size):
            dims = tuple(sizes[d] for d in spec.dims)
            steps.create_dataset(
                spec.name,
                shape=(0, *dims),
                maxshape=(None, *dims),
                chunks=(_CHUNK_ROWS, *dims),
                dtype=np.dtype(spec.dtype),
            )
        steps.attrs["n_complete"] = np.int64(0)
        if raw:
            f.create_group("raw")

    build_file(path, overwrite, fill)
    log.info("created stepped-sine file %s (%d channels, %d orders)", path, n_ch, n_ord)
    return SteppedSineWriter._attach(path, h5py.File(path, "r+"))


def open_for_resume(path: str | PathLike[str]) -> SteppedSineWriter:
    """Reopen an unfinished stepped-sine file to add the steps still missing.

    The file is validated; rows beyond ``n_complete`` (a step in progress when the run died) and
    raw data of steps that did not complete are removed; ``exit_status`` goes back to
    ``"running"``, and the resumption (time, steps on disk, the plan index resumed from, how the
    interrupted run had ended) is appended to the root attribute ``resumes``. A version-1 file
    becomes a version-2 file (its layout is otherwise the same). Skip the plan steps in
    :attr:`SteppedSineWriter.completed_plan_indices`.

    Raises
    ------
    MeasurementFileError
        If the file is invalid, not a stepped-sine file, or its run ended with ``"success"``.
    """
    path = Path(path)
    data = _load_for_update(path)
    if not isinstance(data, SteppedSineData):
        raise MeasurementFileError(
            path, "/", f"kind {KIND_STEPPED_SINE!r}", "kind 'random'", "kind"
        )
    if data.complete:
        raise MeasurementFileError(
            path,
            "/",
            "an unfinished run (complete false)",
            "a run that ended with success",
            "complete",
        )
    f = h5py.File(path, "r+")
    try:
        n = data.n_steps
        fields = step_fields(data.extra_orders_num.size)
        for spec in fields:
            ds = f["steps"][spec.name]
            if ds.chunks is None or ds.maxshape[0] is not None:
                raise MeasurementFileError(
                    path,
                    ds.name,
                    "a dataset resizable along axis 0 (chunked, maxshape None) to append to",
                    f"a fixed-size dataset (maxshape {ds.maxshape})",
                )
        for spec in fields:
            ds = f["steps"][spec.name]
            if ds.shape[0] != n:
                ds.resize(n, axis=0)
        if "raw" in f:
            done = set(data.plan_index.tolist())
            for key in [k for k in f["raw"] if int(k) not in done]:
                log.info("%s: removing /raw/%s of a step that did not complete", path, key)
                del f["raw"][key]
        previous = data.exit_status
        done = set(data.plan_index.tolist())
        event = {
            "time": datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
            "steps_on_disk": int(n),
            "next_plan_index": next(i for i in range(len(done) + 1) if i not in done),
            "previous_status": previous,
            "previous_message": data.exit_message,
        }
        events = [dataclasses.asdict(e) for e in data.resumes] + [event]
        if data.format_version < FORMAT_VERSION:
            log.info(
                "%s: format_version %d -> %d (the resume is recorded)",
                path,
                data.format_version,
                FORMAT_VERSION,
            )
            f.attrs["format_version"] = np.int64(FORMAT_VERSION)
        f.attrs["resumes"] = json.dumps(events, ensure_ascii=False)
        f.attrs["output_at_zero"] = np.bool_(True)
        f.attrs["complete"] = np.bool_(False)
        f.attrs["exit_status"] = "running"
        f.attrs["exit_message"] = ""
        f.flush()
    except BaseException:
        f.close()
        raise
    log.info("resuming %s: %d steps done, previous exit_status %r", path, n, previous)
    return SteppedSineWriter._attach(path, f, data)


def note_output_not_at_zero(path: str | PathLike[str], message: str) -> None:
    """Record in a finished file (a random run's, written before the output was stopped) that
    the ramp of the output to 0 V failed: ``output_at_zero`` false, ``exit_message`` set."""
    with h5py.File(path, "r+") as f:
        if f.attrs.get("format_version", 1) >= 2:
            f.attrs["output_at_zero"] = np.bool_(False)
        f.attrs["exit_message"] = message


def _load_for_update(path: Path) -> SteppedSineData | RandomData:
    with open_file(path) as f:
        return load_open_file(f, path)


class SteppedSineWriter:
    """Appends steps to an open stepped-sine file; create with :func:`create_stepped_sine` or
    :func:`open_for_resume`.

    Used as a context manager, leaving the block by an exception finishes the run as
    ``"failed"`` (``"aborted"`` for ``KeyboardInterrupt``) with the exception text; leaving it
    normally without :meth:`finish` finishes it as ``"aborted"``. Steps already appended are
    never lost.
    """

    _path: Path
    _file: h5py.File | None
    _channels: tuple[ChannelInfo, ...]
    _n_levels: int
    _n_orders: int
    _n_extra: int
    _fields: tuple[ArraySpec, ...]
    _drive: int
    _completed: set[int]
    _n: int

    def __init__(self) -> None:
        raise TypeError("use create_stepped_sine() or open_for_resume() to get a writer")

    @classmethod
    def _attach(
        cls, path: Path, f: h5py.File, data: SteppedSineData | None = None
    ) -> SteppedSineWriter:
        self = object.__new__(cls)
        self._path = path
        self._file = f
        if data is None:
            loaded = load_open_file(f, path)
            assert isinstance(loaded, SteppedSineData)  # the writers open stepped-sine files
            data = loaded
        self._channels = data.channels
        self._n_levels = int(data.levels_n.size)
        self._n_orders = int(data.orders_num.size)
        self._n_extra = int(data.extra_orders_num.size)
        self._fields = step_fields(self._n_extra)
        self._drive = drive_force_index(data.channels)
        self._completed = set(data.plan_index.tolist())
        self._n = data.n_steps
        return self

    # -- state ---------------------------------------------------------------------------------
    @property
    def path(self) -> Path:
        """The file being written."""
        return self._path

    @property
    def channels(self) -> tuple[ChannelInfo, ...]:
        """Channels of the file, in table order."""
        return self._channels

    @property
    def n_complete(self) -> int:
        """Number of steps on disk."""
        return self._n

    @property
    def completed_plan_indices(self) -> set[int]:
        """Plan indices of the steps on disk (a copy)."""
        return set(self._completed)

    @property
    def closed(self) -> bool:
        """True once :meth:`finish` (or :meth:`close`) has run."""
        return self._file is None

    def _require_open(self) -> h5py.File:
        if self._file is None:
            raise ValueError(f"{self._path}: the writer is finished; reopen with open_for_resume")
        return self._file

    # -- writing -------------------------------------------------------------------------------
    def append_step(self, record: StepRecord) -> None:
        """Write one completed step, flush it, then count it in ``n_complete``.

        Parameters
        ----------
        record : StepRecord
            With ``response`` of shape (C, H) for this file's channels and orders.

        Raises
        ------
        MeasurementFileError
            If the record does not fit the file (shapes, level index, drive-force copy) or its
            ``plan_index`` is already stored; nothing is written then.
        """
        f = self._require_open()
        row = self._check_record(record)
        n = self._n
        steps = f["steps"]
        for spec in self._fields:
            self._write_row(steps[spec.name], n, row[spec.name])
        f.flush()
        steps.attrs["n_complete"] = np.int64(n + 1)
        f.flush()
        self._n = n + 1
        self._completed.add(record.plan_index)
        log.debug(
            "%s: step plan_index %d written (%d on disk)", self._path, record.plan_index, n + 1
        )

    def _check_record(self, record: StepRecord) -> dict[str, Any]:
        if not isinstance(record, StepRecord):
            self._reject("/steps", "a StepRecord", type(record).__name__)
        if record.plan_index in self._completed:
            self._reject(
                "/steps/plan_index", "a plan index not yet stored", f"{record.plan_index} again"
            )
        if record.level_index >= self._n_levels:
            self._reject(
                "/steps/level_index",
                f"a value < {self._n_levels} (rows of /levels)",
                str(record.level_index),
            )
        want = (len(self._channels), self._n_orders)
        if record.response.shape != want:
            self._reject(
                "/steps/response", f"shape (C, H) = {want} per step", f"{record.response.shape}"
            )
        try:
            record.check_drive_force(self._drive)
        except FieldValueError as exc:
            self._reject(f"/steps/{exc.field}", exc.expected, exc.found)
        extra = None if record.extra_force is None else record.extra_force.shape
        if extra != ((self._n_extra,) if self._n_extra else None):
            expected = (
                f"shape ({self._n_extra},) per step" if self._n_extra else "none (no /extra_orders)"
            )
            found = "none" if extra is None else f"shape {extra}"
            self._reject("/steps/extra_force", expected, found)
        return {spec.name: getattr(record, spec.field) for spec in self._fields}

    def _reject(self, location: str, expected: str, found: str) -> NoReturn:
        raise MeasurementFileError(self._path, location, expected, found)

    def _write_row(self, dataset: h5py.Dataset, row: int, value: Any) -> None:
        """Make ``dataset`` exactly ``row + 1`` rows long and write its last row."""
        dataset.resize(row + 1, axis=0)
        dataset[row] = value

    def append_raw(self, plan_index: int, samples: Any, fs_hz: float, t0_s: float) -> None:
        """Store the raw time data of a step as ``/raw/<plan_index>`` (file created with raw=True).

        Parameters
        ----------
        plan_index : int
            The step's plan index (>= 0), not stored before.
        samples : array_like, shape (n_samples, C), channel units
            Stored as float32.
        fs_hz : float
            Sampling rate [Hz].
        t0_s : float
            Time of the first sample after the drive started [s].
        """
        f = self._require_open()
        if "raw" not in f:
            self._reject("/raw", "a /raw group (create the file with raw=True)", "none")
        p = check_int(plan_index, owner="append_raw", field="plan_index", minimum=0)
        loc = f"/raw/{p}"
        if str(p) in f["raw"]:
            self._reject(loc, "a plan index without raw data", "raw data already stored")
        data = check_array(
            samples,
            dtype="float64",
            shape=(None, len(self._channels)),
            owner="append_raw",
            field="samples",
        )
        fs = check_float(fs_hz, owner="append_raw", field="fs_hz", positive=True)
        t0 = check_float(t0_s, owner="append_raw", field="t0_s")
        ds = f["raw"].create_dataset(str(p), data=data.astype(np.float32))
        ds.attrs["fs"] = fs
        ds.attrs["t0"] = t0
        f.flush()

    # -- ending --------------------------------------------------------------------------------
    def finish(self, status: str, message: str = "", output_at_zero: bool = True) -> None:
        """End the run: set ``complete`` (true only for ``"success"``), ``exit_status``,
        ``exit_message``, ``output_at_zero``; flush and close the file.

        Parameters
        ----------
        status : {"success", "aborted", "failed"}
        message : str
            Why the run ended (free text, may be empty).
        output_at_zero : bool
            Whether the ramp of the output to 0 V at the end of the run completed.
        """
        if status not in FINAL_STATUSES:
            raise ValueError(f"finish: status must be one of {FINAL_STATUSES}, got {status!r}")
        if not isinstance(message, str):
            raise ValueError(f"finish: message must be a string, got {type(message).__name__}")
        f = self._require_open()
        try:
            for spec in self._fields:  # drop a partly written row left by a failed append
                ds = f["steps"][spec.name]
                if ds.shape[0] != self._n:
                    ds.resize(self._n, axis=0)
            f.attrs["complete"] = np.bool_(status == "success")
            f.attrs["exit_status"] = status
            f.attrs["exit_message"] = message
            f.attrs["output_at_zero"] = np.bool_(output_at_zero)
            f.flush()
        finally:
            f.close()
            self._file = None
        log.info("%s finished: %s (%d steps) %s", self._path, status, self._n, message)

    def close(self) -> None:
        """Finish as ``"aborted"`` if the run was not finished; nothing otherwise."""
        if self._file is not None:
            log.warning("%s: closed before finish(); marking the run aborted", self._path)
            self.finish("aborted", "the writer was closed before the run finished")

    def __enter__(self) -> SteppedSineWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._file is None:
            return
        if exc is None:
            self.close()
            return
        status = "aborted" if isinstance(exc, KeyboardInterrupt) else "failed"
        try:
            self.finish(status, f"{type(exc).__name__}: {exc}")
        except Exception:  # never hide the original exception
            log.exception("%s: could not record the end of the run", self._path)
