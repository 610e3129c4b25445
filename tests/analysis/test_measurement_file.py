"""The measurement-file contract: round trips, run ends, crash safety, resume, validation."""

from __future__ import annotations

import dataclasses
import json
import pickle
import subprocess
import sys
import textwrap
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from fractions import Fraction
from pathlib import Path

import h5py
import numpy as np
import pytest

from analysis.measurement_file import (
    CHANNEL_FIELDS,
    FORMAT_VERSION,
    ChannelInfo,
    FieldValueError,
    MeasurementFileError,
    RandomData,
    SteppedSineData,
    StepRecord,
    create_stepped_sine,
    open_for_resume,
    read_measurement,
    read_raw,
    safe_std,
)
from analysis.measurement_file.schema import STEP_FIELDS, channel_table_dtype
from tests.analysis import measurement_samples as ms

ROOT = Path(__file__).resolve().parents[2]


def _read_stepped(path: Path) -> SteppedSineData:
    data = read_measurement(path)
    assert isinstance(data, SteppedSineData)
    return data


def _assert_steps_equal(data: SteppedSineData, records: list[StepRecord]) -> None:
    assert data.n_steps == len(records)
    for spec in STEP_FIELDS:
        expected = np.array([getattr(r, spec.field) for r in records])
        np.testing.assert_array_equal(getattr(data, spec.field), expected, err_msg=spec.name)


# -- round trips ---------------------------------------------------------------------------------
def test_stepped_sine_round_trip(tmp_path: Path) -> None:
    records = ms.sample_step_records()
    before = datetime.now(UTC) - timedelta(seconds=2)
    path = ms.write_sample_stepped_sine(tmp_path / "run.h5", records=records)
    data = _read_stepped(path)

    assert len(records) == 20 and data.n_steps == 20
    _assert_steps_equal(data, records)
    assert data.channels == ms.sample_channels()
    assert data.actuator == ms.sample_actuator()
    np.testing.assert_array_equal(data.levels_n, ms.LEVELS_N)
    assert data.orders == (Fraction(1), Fraction(2), Fraction(3))
    np.testing.assert_array_equal(data.force_targets, ms.sample_force_targets())
    assert data.config == {"kind": "stepped-sine", "levels_n": [2.0, 4.0]}
    assert data.setup["daq"] == "simulated"
    assert data.complete is True and data.exit_status == "success" and data.exit_message == ""
    assert data.format_version == FORMAT_VERSION
    assert before <= data.created <= datetime.now(UTC)
    assert {"numpy", "h5py", "scipy"} <= set(data.software)
    assert data.raw_plan_indices == ()
    with pytest.raises(ValueError):
        data.response[0, 0, 0] = 0  # read-only


def test_extra_force_orders_round_trip_take_and_resume(tmp_path: Path) -> None:
    """The drive force at orders the drive does not contain is stored beside the orders'."""
    rng = np.random.default_rng(3)
    records = [
        dataclasses.replace(
            r,
            extra_force=rng.normal(size=2) + 1j * rng.normal(size=2),
            extra_force_std=np.full(2, 1e-3 * (i + 1)),
        )
        for i, r in enumerate(ms.sample_step_records())
    ]
    kwargs = ms.sample_stepped_sine_kwargs() | {
        "extra_orders_num": [4, 5],
        "extra_orders_den": [1, 1],
    }
    path = tmp_path / "run.h5"
    with create_stepped_sine(path, **kwargs) as writer:
        for r in records[:12]:
            writer.append_step(r)
        with pytest.raises(MeasurementFileError, match=r"/steps/extra_force.*shape \(2,\)"):
            writer.append_step(
                dataclasses.replace(records[12], extra_force=None, extra_force_std=None)
            )
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["extra_orders_num"][()], [4, 5])
        assert f["steps/extra_force"].shape == (12, 2)
    with open_for_resume(path) as writer:
        for r in records[12:]:
            writer.append_step(r)
        writer.finish("success")
    data = _read_stepped(path)
    _assert_steps_equal(data, records)
    assert data.extra_orders == (Fraction(4), Fraction(5))
    np.testing.assert_array_equal(data.extra_force, [r.extra_force for r in records])
    np.testing.assert_array_equal(data.extra_force_std, [r.extra_force_std for r in records])
    part = data.take([3, 1])
    np.testing.assert_array_equal(part.extra_force, data.extra_force[[3, 1]])

    plain = _read_stepped(ms.write_sample_stepped_sine(tmp_path / "plain.h5"))
    assert plain.extra_orders == () and plain.extra_force.shape == (20, 0)
    with create_stepped_sine(tmp_path / "p2.h5", **ms.sample_stepped_sine_kwargs()) as writer:
        with pytest.raises(MeasurementFileError, match="no /extra_orders"):
            writer.append_step(records[0])
        writer.finish("aborted")
    with pytest.raises(FieldValueError, match="orders the drive does not contain"):
        create_stepped_sine(
            tmp_path / "bad.h5",
            **ms.sample_stepped_sine_kwargs() | {"extra_orders_num": [3], "extra_orders_den": [1]},
        )
    with pytest.raises(FieldValueError, match="extra_force_std"):
        dataclasses.replace(records[0], extra_force_std=np.zeros(3))


def test_extra_force_orders_need_both_datasets(tmp_path: Path) -> None:
    kwargs = ms.sample_stepped_sine_kwargs() | {"extra_orders_num": [4], "extra_orders_den": [1]}
    path = tmp_path / "run.h5"
    with create_stepped_sine(path, **kwargs) as writer:
        writer.finish("success")
    with h5py.File(path, "r+") as f:
        del f["extra_orders_den"]
    with pytest.raises(MeasurementFileError, match="/extra_orders_den.*beside /extra_orders_num"):
        read_measurement(path)


def test_stepped_sine_on_disk_layout(tmp_path: Path) -> None:
    path = ms.write_sample_stepped_sine(tmp_path / "run.h5")
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "rig-measurement"
        assert f.attrs["format_version"].dtype == np.int64
        assert f.attrs["kind"] == "stepped-sine"
        assert isinstance(f.attrs["complete"], np.bool_)
        assert datetime.fromisoformat(f.attrs["created"]).utcoffset() == timedelta(0)
        assert json.loads(f.attrs["software"])["numpy"] == np.__version__
        table = f["setup/channels"]
        assert table.dtype.names == CHANNEL_FIELDS
        info = h5py.check_string_dtype(table.dtype.fields["name"][0])
        assert info is not None and info.encoding == "utf-8" and info.length is None
        assert f["setup/actuator"].attrs["point"] == 3
        force_type = f["steps/force"].id.get_type()
        assert force_type.get_class() == h5py.h5t.COMPOUND
        assert [force_type.get_member_name(i) for i in range(2)] == [b"r", b"i"]
        assert f["steps/control_converged"].dtype == np.bool_
        assert f["steps/sweep_direction"].dtype == np.int8
        for spec in STEP_FIELDS:
            ds = f["steps"][spec.name]
            assert ds.maxshape[0] is None and ds.chunks is not None, spec.name
            assert ds.shape[0] == 20
        assert f["steps"].attrs["n_complete"] == 20


def test_select_and_frf(tmp_path: Path) -> None:
    data = _read_stepped(ms.write_sample_stepped_sine(tmp_path / "run.h5"))
    down = data.select(level_index=1, sweep_direction=-1)
    assert down.n_steps == 5
    np.testing.assert_array_equal(down.frequency_target_hz, ms.FREQUENCIES_HZ[::-1])
    assert set(down.level_index.tolist()) == {1} and set(down.sweep_direction.tolist()) == {-1}
    assert data.select(level_index=[0, 1]).n_steps == 20
    assert data.select(sweep_direction=1).n_steps == 10

    orders = np.array([1.0, 2.0, 3.0])
    expected = ms.accelerance(down.frequency_target_hz[:, None] * orders)
    np.testing.assert_allclose(down.frf("acc3"), expected, rtol=1e-12)
    np.testing.assert_allclose(down.frf("acc7"), ms.TIP_FACTOR * expected, rtol=1e-12)
    np.testing.assert_allclose(data.frf("force3"), 1.0)
    assert data.channel_index("acc7") == 2 and data.drive_force_index == 0
    assert [ch.name for ch in data.response_channels()] == ["acc7"]
    assert data.order_index("3") == 2
    with pytest.raises(KeyError, match="no channel named 'nope'"):
        data.channel_index("nope")
    with pytest.raises(IndexError):
        data.select(level_index=2)


def test_random_round_trip(tmp_path: Path) -> None:
    frf = ms.sample_random_frf()
    data = read_measurement(ms.write_sample_random(tmp_path / "random.h5"))
    assert isinstance(data, RandomData)
    np.testing.assert_array_equal(data.frequency_hz, frf.frequency_hz)
    np.testing.assert_array_equal(data.h1, frf.h1)
    np.testing.assert_array_equal(data.coherence, frf.coherence)
    np.testing.assert_array_equal(data.force_psd, frf.force_psd)
    assert (data.estimator, data.n_averages, data.window) == ("H1", 50, "hann")
    assert (data.overlap, data.fs_hz, data.rms_force_n) == (0.5, 1024.0, 0.3)
    assert data.complete and data.exit_status == "success"
    assert data.channels == ms.sample_channels()
    np.testing.assert_array_equal(data.frf("acc7"), frf.h1[:, 2])


# -- run-end semantics -----------------------------------------------------------------------
@pytest.mark.parametrize("status", ["success", "aborted", "failed"])
def test_finish_sets_complete_only_for_success(tmp_path: Path, status: str) -> None:
    data = _read_stepped(ms.write_sample_stepped_sine(tmp_path / "run.h5", status=status))
    assert data.exit_status == status
    assert data.complete is (status == "success")
    assert data.exit_message == ("" if status == "success" else f"sample run {status}")
    assert data.n_steps == 20


def test_exception_inside_writer_finishes_failed_and_keeps_steps(tmp_path: Path) -> None:
    records = ms.sample_step_records()
    path = tmp_path / "run.h5"
    with (
        pytest.raises(RuntimeError, match="DAQ lost"),
        create_stepped_sine(path, **ms.sample_stepped_sine_kwargs()) as writer,
    ):
        for record in records[:3]:
            writer.append_step(record)
        raise RuntimeError("DAQ lost")
    assert writer.closed
    data = _read_stepped(path)
    _assert_steps_equal(data, records[:3])
    assert data.exit_status == "failed" and not data.complete
    assert data.exit_message == "RuntimeError: DAQ lost"


def test_leaving_writer_without_finish_marks_aborted(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    with create_stepped_sine(path, **ms.sample_stepped_sine_kwargs()) as writer:
        writer.append_step(ms.sample_step_records()[0])
    data = _read_stepped(path)
    assert data.exit_status == "aborted" and not data.complete and data.n_steps == 1
    with pytest.raises(ValueError, match="finished"):
        writer.append_step(ms.sample_step_records()[1])


def test_append_refuses_bad_steps_and_writes_nothing(tmp_path: Path) -> None:
    records = ms.sample_step_records()
    path = tmp_path / "run.h5"
    writer = create_stepped_sine(path, **ms.sample_stepped_sine_kwargs())
    writer.append_step(records[0])
    writer.append_step(records[1])
    good = records[2]
    bad = {
        "/steps/plan_index": dataclasses.replace(good, plan_index=1),
        "/steps/response": dataclasses.replace(
            good, response=good.response[:2], response_std=good.response_std[:2]
        ),
        "/steps/level_index": dataclasses.replace(good, level_index=2),
        "/steps/force": dataclasses.replace(good, force=good.force * 1.1),
    }
    for location, record in bad.items():
        with pytest.raises(MeasurementFileError) as info:
            writer.append_step(record)
        assert info.value.location == location and location in str(info.value)
        assert str(path) in str(info.value)
    assert writer.n_complete == 2 and writer.completed_plan_indices == {0, 1}
    writer.finish("success")
    with h5py.File(path, "r") as f:
        assert all(f["steps"][spec.name].shape[0] == 2 for spec in STEP_FIELDS)
    _assert_steps_equal(_read_stepped(path), records[:2])


def test_create_refuses_existing_file(tmp_path: Path) -> None:
    path = ms.write_sample_stepped_sine(tmp_path / "run.h5")
    with pytest.raises(FileExistsError):
        create_stepped_sine(path, **ms.sample_stepped_sine_kwargs())
    assert _read_stepped(path).n_steps == 20
    create_stepped_sine(path, **ms.sample_stepped_sine_kwargs(), overwrite=True).finish("failed")
    assert _read_stepped(path).n_steps == 0
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_raw_round_trip(tmp_path: Path) -> None:
    records = ms.sample_step_records()[:2]
    samples = np.random.default_rng(1).standard_normal((256, 3))
    path = tmp_path / "run.h5"
    with create_stepped_sine(path, **ms.sample_stepped_sine_kwargs(), raw=True) as writer:
        for record in records:
            writer.append_raw(record.plan_index, samples, fs_hz=2048.0, t0_s=0.25)
            writer.append_step(record)
        with pytest.raises(MeasurementFileError, match="/raw/1"):
            writer.append_raw(1, samples, fs_hz=2048.0, t0_s=0.25)
        writer.finish("success")
    assert _read_stepped(path).raw_plan_indices == (0, 1)
    raw = read_raw(path, 1)
    assert raw.samples.dtype == np.float32 and raw.samples.shape == (256, 3)
    np.testing.assert_array_equal(raw.samples, samples.astype(np.float32))
    assert (raw.fs_hz, raw.t0_s) == (2048.0, 0.25)
    with pytest.raises(KeyError):
        read_raw(path, 7)


# -- crash and resume ------------------------------------------------------------------------
_KILLED_WRITER = """
import os, sys
import numpy as np
sys.path.insert(0, {root!r})
from analysis.measurement_file import create_stepped_sine
from analysis.measurement_file.writer import SteppedSineWriter
from tests.analysis import measurement_samples as ms

records = ms.sample_step_records()
writer = create_stepped_sine({path!r}, **ms.sample_stepped_sine_kwargs(), raw=True)
for record in records[:3]:
    writer.append_step(record)
writer.append_raw(3, np.zeros((16, 3)), 1024.0, 0.0)
original = SteppedSineWriter._write_row
written = []

def dying(self, dataset, row, value):
    original(self, dataset, row, value)
    written.append(dataset.name)
    if len(written) == 7:
        self._file.flush()  # partial rows of step 4 reach the disk: the worst case for readers
        os._exit(1)

SteppedSineWriter._write_row = dying
writer.append_step(records[3])
"""


def test_killed_writer_leaves_completed_steps_and_resume_finishes_run(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    script = textwrap.dedent(_KILLED_WRITER).format(root=str(ROOT), path=str(path))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=60)
    assert proc.returncode == 1, proc.stderr.decode()
    with h5py.File(path, "r") as f:  # the 4th step is half on disk
        assert f["steps/plan_index"].shape[0] == 4 and f["steps/drive"].shape[0] == 3

    records = ms.sample_step_records()
    data = _read_stepped(path)
    _assert_steps_equal(data, records[:3])
    assert data.exit_status == "running" and not data.complete
    assert data.raw_plan_indices == ()

    writer = open_for_resume(path)
    assert writer.completed_plan_indices == {0, 1, 2}
    with writer:
        for record in records:
            if record.plan_index not in writer.completed_plan_indices:
                writer.append_step(record)
        writer.finish("success", "resumed once")
    data = _read_stepped(path)
    _assert_steps_equal(data, records)
    assert data.complete and data.exit_message == "resumed once"
    with h5py.File(path, "r") as f:
        assert list(f["raw"]) == []  # raw data of the lost step were dropped on resume


def test_resume_of_aborted_run_and_refusal_of_finished_run(tmp_path: Path) -> None:
    records = ms.sample_step_records()
    path = ms.write_sample_stepped_sine(tmp_path / "run.h5", records=records[:5], status="aborted")
    writer = open_for_resume(path)
    assert writer.n_complete == 5
    for record in records[5:8]:
        writer.append_step(record)
    writer.finish("success")
    _assert_steps_equal(_read_stepped(path), records[:8])
    with pytest.raises(MeasurementFileError, match="complete"):
        open_for_resume(path)
    with pytest.raises(MeasurementFileError, match="kind"):
        open_for_resume(ms.write_sample_random(tmp_path / "random.h5"))


# -- validation ------------------------------------------------------------------------------
def _set_attr(obj: str, name: str, value: object) -> Callable[[h5py.File], None]:
    def mutate(f: h5py.File) -> None:
        f[obj].attrs[name] = value

    return mutate


def _replace(name: str, change: Callable[[np.ndarray], np.ndarray]) -> Callable[[h5py.File], None]:
    def mutate(f: h5py.File) -> None:
        data = change(f[name][()])
        del f[name]
        f[name] = data

    return mutate


def _edit_channels(row: int, **values: object) -> Callable[[h5py.File], None]:
    def change(table: np.ndarray) -> np.ndarray:
        table = table.astype(channel_table_dtype())
        for key, value in values.items():
            table[row][key] = value
        return table

    return _replace("setup/channels", change)


def _edit(name: str, row: int, value: object) -> Callable[[h5py.File], None]:
    def change(a: np.ndarray) -> np.ndarray:
        a[row] = value
        return a

    return _replace(name, change)


def _delete(name: str) -> Callable[[h5py.File], None]:
    def mutate(f: h5py.File) -> None:
        del f[name]

    return mutate


_BAD_STEPPED = {
    "format string": (_set_attr("/", "format", "other-format"), "/", "format"),
    "newer version": (
        _set_attr("/", "format_version", np.int64(FORMAT_VERSION + 1)),
        "/",
        "format_version",
    ),
    "version zero": (_set_attr("/", "format_version", np.int64(0)), "/", "format_version"),
    "unknown kind": (_set_attr("/", "kind", "sweep"), "/", "kind"),
    "complete without success": (_set_attr("/", "exit_status", "failed"), "/", "complete"),
    "bad config json": (_set_attr("/setup", "config_json", "{not json"), "/setup", "config_json"),
    "bad created": (_set_attr("/", "created", "yesterday"), "/", "created"),
    "missing dataset": (_delete("steps/drive"), "/steps/drive", None),
    "missing n_complete": (
        lambda f: f["steps"].attrs.__delitem__("n_complete"),
        "/steps",
        "n_complete",
    ),
    "wrong shape": (
        _replace("steps/response", lambda a: np.concatenate([a, a[:, :, :1]], axis=2)),
        "/steps/response",
        None,
    ),
    "force targets shape": (_replace("force_targets", lambda a: a[:1]), "/force_targets", None),
    "real force": (_replace("steps/force", lambda a: a.real.copy()), "/steps/force", None),
    "bad direction": (_edit_channels(2, direction="w"), "/setup/channels", None),
    "bad role": (_edit_channels(2, role="output"), "/setup/channels", None),
    "two drive-force channels": (
        _edit_channels(1, role="drive-force", quantity="force", unit="N"),
        "/setup/channels",
        None,
    ),
    "duplicate channel name": (_edit_channels(2, name="acc3"), "/setup/channels", None),
    "duplicate plan_index": (_edit("steps/plan_index", 4, 2), "/steps/plan_index", None),
    "level index out of range": (_edit("steps/level_index", 0, 5), "/steps/level_index", None),
    "sweep direction zero": (_edit("steps/sweep_direction", 3, 0), "/steps/sweep_direction", None),
    "nan response": (_edit("steps/response", 6, np.nan), "/steps/response", None),
    "negative std": (_edit("steps/response_std", 6, -1.0), "/steps/response_std", None),
    "force not a copy": (_edit("steps/force", 6, 1.0 + 0j), "/steps/force", None),
    "zero orders_den": (_edit("orders_den", 1, 0), "/orders_den", None),
    "n_complete too large": (
        _set_attr("steps", "n_complete", np.int64(21)),
        "/steps",
        "n_complete",
    ),
    "bad actuator direction": (
        _set_attr("setup/actuator", "direction", "q"),
        "/setup/actuator",
        "direction",
    ),
}


@pytest.mark.parametrize("case", list(_BAD_STEPPED))
def test_invalid_stepped_sine_file_is_reported_with_its_place(tmp_path: Path, case: str) -> None:
    mutate, location, attribute = _BAD_STEPPED[case]
    path = ms.write_sample_stepped_sine(tmp_path / "run.h5")
    with h5py.File(path, "r+") as f:
        mutate(f)
    with pytest.raises(MeasurementFileError) as info:
        read_measurement(path)
    err = info.value
    assert (err.location, err.attribute) == (location, attribute), str(err)
    assert str(path) in str(err) and location in str(err)
    if attribute is not None:
        assert repr(attribute) in str(err)
    assert err.expected and err.found


def test_newer_version_message_says_what_is_unsupported(tmp_path: Path) -> None:
    path = ms.write_sample_stepped_sine(tmp_path / "run.h5")
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = np.int64(FORMAT_VERSION + 1)
    with pytest.raises(
        MeasurementFileError,
        match=rf"format_version at most {FORMAT_VERSION}.*found {FORMAT_VERSION + 1}: .*newer",
    ):
        read_measurement(path)


_BAD_RANDOM = {
    "h1 columns": (_replace("frf/h1", lambda a: a[:, :2]), "/frf/h1", None),
    "coherence above one": (_edit("frf/coherence", 3, 1.5), "/frf/coherence", None),
    "drive column not one": (_edit("frf/h1", 3, 2.0), "/frf/h1", None),
    "decreasing frequency": (_edit("frf/frequency", 3, 0.0), "/frf/frequency", None),
    "estimator": (_set_attr("frf", "estimator", "H2"), "/frf", "estimator"),
    "overlap": (_set_attr("frf", "overlap", 1.0), "/frf", "overlap"),
}


@pytest.mark.parametrize("case", list(_BAD_RANDOM))
def test_invalid_random_file_is_reported_with_its_place(tmp_path: Path, case: str) -> None:
    mutate, location, attribute = _BAD_RANDOM[case]
    path = ms.write_sample_random(tmp_path / "random.h5")
    with h5py.File(path, "r+") as f:
        mutate(f)
    with pytest.raises(MeasurementFileError) as info:
        read_measurement(path)
    assert (info.value.location, info.value.attribute) == (location, attribute), str(info.value)
    assert location in str(info.value)


def test_not_an_hdf5_file_and_missing_file(tmp_path: Path) -> None:
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(MeasurementFileError, match="an HDF5 file"):
        read_measurement(text)
    with pytest.raises(FileNotFoundError):
        read_measurement(tmp_path / "absent.h5")


def test_error_is_picklable_and_a_value_error() -> None:
    err = MeasurementFileError("/data/run.h5", "/steps", "at most 3", "5", "n_complete")
    copy = pickle.loads(pickle.dumps(err))
    assert isinstance(copy, ValueError) and str(copy) == str(err)
    assert str(err) == "/data/run.h5: /steps (attribute 'n_complete'): expected at most 3; found 5"


# -- third-party files -------------------------------------------------------------------------
def _third_party_stepped_sine(path: Path, *, matlab_style: bool) -> dict[str, np.ndarray]:
    """A stepped-sine file written with plain h5py from the contract alone.

    Sub-harmonic orders 1/2, 1, 2; 2 channels; 3 steps stored, n_complete 2 (the 3rd row is a
    step in progress, NaN). ``matlab_style`` writes fixed-length strings, int32/float32 and
    uint8 booleans, integer attributes as doubles, non-resizable datasets: what generic HDF5
    tools tend to produce.
    """
    rng = np.random.default_rng(5)
    n, h = 3, 3
    force = rng.standard_normal((n, h)) + 1j * rng.standard_normal((n, h))
    response = np.stack([force, 3 * force], axis=1)
    response[2] = np.nan
    std = np.abs(response) * 0.01
    steps = {
        "plan_index": np.array([4, 0, 9]),
        "level_index": np.array([0, 0, 0]),
        "sweep_direction": np.array([1, -1, 1], dtype=np.int8),
        "frequency_target": np.array([20.0, 21.0, 22.0]),
        "frequency": np.array([20.0, 21.0, 22.0]),
        "force": force,
        "force_std": std[:, 0, :],
        "response": response,
        "response_std": std,
        "drive": 0.2 * force,
        "n_blocks": np.array([4, 4, 4]),
        "control_iterations": np.array([0, 2, 1]),
        "control_converged": np.array([True, False, True]),
        "control_error": np.array([0.0, 0.1, 0.2]),
        "timestamp": np.array([1.0, 2.0, 3.0]),
    }
    text = (lambda s: np.bytes_(s.encode())) if matlab_style else str
    s_dt = "S16" if matlab_style else h5py.string_dtype()
    with h5py.File(path, "w") as f:
        f.attrs["format"] = text("rig-measurement")
        f.attrs["format_version"] = np.array([1.0]) if matlab_style else 1
        f.attrs["kind"] = text("stepped-sine")
        f.attrs["created"] = text("2024-03-01T09:30:00Z")
        f.attrs["software"] = text('{"labview-export": "2.1"}')
        f.attrs["complete"] = np.uint8(0) if matlab_style else False
        f.attrs["exit_status"] = text("failed")
        f.attrs["exit_message"] = text("amplifier tripped")
        setup = f.create_group("setup")
        setup.attrs["config_json"] = text('{"plan": "custom"}')
        setup.attrs["setup_json"] = text("{}")
        dt = np.dtype(
            [
                ("name", s_dt),
                ("point", np.int32 if matlab_style else np.int64),
                ("direction", s_dt),
                ("quantity", s_dt),
                ("unit", s_dt),
                ("sensitivity", np.float64),
                ("sensitivity_unit", s_dt),
                ("role", s_dt),
                ("mass_kg", np.float64),
                ("serial", s_dt),
                ("comment", s_dt),  # an extension field
            ]
        )
        rows = [
            ("F", 3, "y", "force", "N", 22.0, "mV/N", "drive-force", 0.0, "", "x"),
            ("tip", 7, "-y", "displacement", "m", 1.0, "V/m", "response", 0.0, "L1", "y"),
        ]
        if matlab_style:
            rows = [tuple(v.encode() if isinstance(v, str) else v for v in r) for r in rows]
        f.create_dataset("setup/channels", data=np.array(rows, dtype=dt))
        f.create_group("setup/actuator")
        f["setup/actuator"].attrs["point"] = 3
        f["setup/actuator"].attrs["direction"] = text("y")
        f["levels"] = np.array([1.5], dtype=np.float32 if matlab_style else np.float64)
        f["orders_num"] = np.array([1, 1, 2], dtype=np.int32 if matlab_style else np.int64)
        f["orders_den"] = np.array([2, 1, 1], dtype=np.int32 if matlab_style else np.int64)
        f["force_targets"] = np.array([[0.03, 1.5, 0.03]], dtype=complex)
        g = f.create_group("steps")
        for name, value in steps.items():
            if matlab_style and name == "control_converged":
                value = value.astype(np.uint8)
            elif matlab_style and value.dtype == np.int64:
                value = value.astype(np.int32)
            g[name] = value
        g.attrs["n_complete"] = 2.0 if matlab_style else 2
    return steps


@pytest.mark.parametrize("matlab_style", [False, True], ids=["contract", "matlab-style"])
def test_third_party_file_reads_back(tmp_path: Path, matlab_style: bool) -> None:
    path = tmp_path / "third_party.h5"
    steps = _third_party_stepped_sine(path, matlab_style=matlab_style)
    data = _read_stepped(path)
    assert data.n_steps == 2
    for spec in STEP_FIELDS:
        got = getattr(data, spec.field)
        assert got.dtype == np.dtype(spec.dtype), spec.name
        np.testing.assert_array_equal(got, steps[spec.name][:2], err_msg=spec.name)
    assert data.orders == (Fraction(1, 2), Fraction(1), Fraction(2))
    assert data.order_index("1/2") == 0
    assert [ch.name for ch in data.channels] == ["F", "tip"]
    assert data.channels[1] == ChannelInfo(
        "tip", 7, "-y", "displacement", "m", 1.0, "V/m", "response", 0.0, "L1"
    )
    assert data.created == datetime(2024, 3, 1, 9, 30, tzinfo=UTC)
    assert data.software == {"labview-export": "2.1"}
    assert (data.complete, data.exit_status, data.exit_message) == (
        False,
        "failed",
        "amplifier tripped",
    )
    np.testing.assert_allclose(data.frf("tip"), 3.0)


def test_resume_refuses_fixed_size_datasets(tmp_path: Path) -> None:
    path = tmp_path / "third_party.h5"
    _third_party_stepped_sine(path, matlab_style=False)
    with pytest.raises(MeasurementFileError, match="/steps/plan_index.*resizable"):
        open_for_resume(path)
    assert _read_stepped(path).exit_status == "failed"  # left unchanged


# -- records -----------------------------------------------------------------------------------
def test_records_validate_fields_on_construction() -> None:
    with pytest.raises(FieldValueError, match=r"ChannelInfo 'a'\.direction") as info:
        ChannelInfo("a", 1, "up", "acceleration", "m/s^2", 10.0, "mV/g", "response")
    assert info.value.field == "direction" and info.value.found == "'up'"
    with pytest.raises(FieldValueError, match="quantity"):
        ChannelInfo("f", 1, "y", "acceleration", "m/s^2", 10.0, "mV/g", "drive-force")
    with pytest.raises(FieldValueError, match="mass_kg"):
        ChannelInfo("a", 1, "y", "acceleration", "m/s^2", 10.0, "mV/g", "response", -1.0)
    good = ms.sample_step_records()[0]
    with pytest.raises(FieldValueError, match="response_std"):
        dataclasses.replace(good, response_std=good.response_std[:, :2])
    with pytest.raises(FieldValueError, match="sweep_direction"):
        dataclasses.replace(good, sweep_direction=0)
    with pytest.raises(FieldValueError, match="frequency_hz"):
        dataclasses.replace(good, frequency_hz=float("nan"))
    with pytest.raises(FieldValueError, match="plan_index"):
        dataclasses.replace(good, plan_index=1.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        good.plan_index = 3  # type: ignore[misc]


def test_create_validates_plan_and_channels(tmp_path: Path) -> None:
    kwargs = ms.sample_stepped_sine_kwargs()
    with pytest.raises(FieldValueError, match="orders_num.*distinct"):
        create_stepped_sine(tmp_path / "a.h5", **{**kwargs, "orders_num": [1, 2, 2]})
    with pytest.raises(FieldValueError, match="force_targets"):
        create_stepped_sine(tmp_path / "a.h5", **{**kwargs, "force_targets": np.ones((2, 2))})
    with pytest.raises(FieldValueError, match="drive-force"):
        create_stepped_sine(tmp_path / "a.h5", **{**kwargs, "channels": kwargs["channels"][1:]})
    with pytest.raises(ValueError, match="config"):
        create_stepped_sine(tmp_path / "a.h5", **{**kwargs, "config": {"x": float("nan")}})
    assert list(tmp_path.iterdir()) == []


def test_safe_std_floors_zero_std() -> None:
    std = np.array([[0.0, 1e-3], [2.0, 0.0]])
    out = safe_std(std, 1e-6)
    np.testing.assert_array_equal(out, [[1e-6, 1e-3], [2.0, 1e-6]])
    assert np.all(np.isfinite(1.0 / out))
    with pytest.raises(ValueError, match="floor"):
        safe_std(std, 0.0)
