"""Low-level writes shared by the stepped-sine and random writers: root, ``/setup``, files.

Files are first built under a temporary name beside the target and moved into place with
:func:`os.replace`, so a crash while a file is being created never leaves a half-made file under
the target name.
"""

from __future__ import annotations

import json
import logging
import os
import platform
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .records import Actuator, ChannelInfo
from .schema import CHANNEL_FIELDS, FORMAT, FORMAT_VERSION, channel_table_dtype

__all__ = ["OutputExistsError", "build_file", "software_versions", "write_header"]

log = logging.getLogger(__name__)

_SOFTWARE_PACKAGES = ("clearance-rig", "numpy", "scipy", "h5py")


def software_versions(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Versions of the packages that wrote a file: package name -> version.

    Parameters
    ----------
    extra : mapping of str to str, optional
        More entries (e.g. a DAQ driver's version); they override the defaults.
    """
    versions: dict[str, str] = {"python": platform.python_version()}
    for package in _SOFTWARE_PACKAGES:
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            log.debug("package %s is not installed; not recorded in 'software'", package)
    versions["hdf5"] = h5py.version.hdf5_version
    for key, value in (extra or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise ValueError(f"software: keys and versions must be strings, got {key!r}: {value!r}")
        versions[key] = value
    return versions


def to_json(value: Any, what: str) -> str:
    """Serialise a mapping as strict JSON (no NaN/inf), naming ``what`` on failure."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{what}: expected a mapping (dict), got {type(value).__name__}")
    try:
        return json.dumps(dict(value), allow_nan=False, ensure_ascii=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what}: not serialisable as JSON: {exc}") from exc


def write_header(
    f: h5py.File,
    *,
    kind: str,
    channels: tuple[ChannelInfo, ...],
    actuator: Actuator,
    config_json: str,
    setup_json: str,
    software: dict[str, str],
    exit_status: str,
) -> None:
    """Write the root attributes, ``/setup`` with its attributes, channel table and actuator."""
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    f.attrs["kind"] = kind
    f.attrs["created"] = datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    f.attrs["software"] = json.dumps(software, ensure_ascii=False)
    f.attrs["complete"] = np.bool_(exit_status == "success")
    f.attrs["exit_status"] = exit_status
    f.attrs["exit_message"] = ""
    f.attrs["output_at_zero"] = np.bool_(True)
    f.attrs["resumes"] = "[]"
    setup = f.create_group("setup")
    setup.attrs["config_json"] = config_json
    setup.attrs["setup_json"] = setup_json
    table = np.array(
        [tuple(getattr(ch, name) for name in CHANNEL_FIELDS) for ch in channels],
        dtype=channel_table_dtype(),
    )
    setup.create_dataset("channels", data=table)
    act = setup.create_group("actuator")
    act.attrs["point"] = np.int64(actuator.point)
    act.attrs["direction"] = actuator.direction
    act.attrs["static_stiffness_n_per_m"] = np.float64(actuator.static_stiffness_n_per_m)


class OutputExistsError(FileExistsError):
    """An output file exists and the caller did not ask to replace it.

    The message names the library's argument (``overwrite=True``); a front end that offers the
    choice under another name (a command line's ``--overwrite``, a GUI's tick box) says it in
    its own words with :meth:`rephrased`, so each user reads the switch that they can use.

    Attributes
    ----------
    path : Path
        The existing file.
    """

    def __init__(self, path: str | os.PathLike[str], option: str = "overwrite=True") -> None:
        self.path = Path(path)
        super().__init__(self.rephrased(option))

    def rephrased(self, option: str) -> str:
        """The message with ``option`` (e.g. ``"--overwrite"``) as the way to replace the file."""
        return f"{self.path}: file exists (pass {option} to replace it)"


def build_file(path: Path, overwrite: bool, fill: Callable[[h5py.File], None]) -> None:
    """Create ``path`` atomically: ``fill`` an HDF5 file under a temporary name, then rename it.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and ``overwrite`` is false (a :class:`FileExistsError`).
    """
    if path.exists() and not overwrite:
        raise OutputExistsError(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        with h5py.File(tmp, "w") as f:
            fill(f)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
