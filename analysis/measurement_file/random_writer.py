"""Write a random-excitation measurement file (H1 FRFs) in one go."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from os import PathLike
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .layout import build_file, software_versions, to_json, write_header
from .records import Actuator, ChannelInfo, RandomFRF, check_channels, drive_force_index
from .schema import KIND_RANDOM, FieldValueError

__all__ = ["write_random"]

log = logging.getLogger(__name__)


def write_random(
    path: str | PathLike[str],
    *,
    channels: Iterable[ChannelInfo],
    actuator: Actuator,
    frf: RandomFRF,
    config: Mapping[str, Any],
    setup: Mapping[str, Any],
    software: Mapping[str, str] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write a complete random-excitation measurement file in one go.

    Parameters
    ----------
    path : str or path-like
    channels : iterable of ChannelInfo
        In table order (``C``); ``frf.h1`` has one column per channel.
    actuator : Actuator
    frf : RandomFRF
        The H1 estimate; its drive-force column must be 1.
    config, setup : mapping
        Run configuration and lab setup, stored as JSON.
    software : mapping of str to str, optional
        Extra package -> version entries.
    overwrite : bool
        Replace an existing file instead of refusing.

    Returns
    -------
    Path
        The file written (``complete`` true, ``exit_status`` ``"success"``).
    """
    path = Path(path)
    if not isinstance(actuator, Actuator):
        raise FieldValueError("write_random", "actuator", "an Actuator", repr(actuator))
    if not isinstance(frf, RandomFRF):
        raise FieldValueError("write_random", "frf", "a RandomFRF", type(frf).__name__)
    chans = check_channels(channels)
    if frf.h1.shape[1] != len(chans):
        raise FieldValueError(
            "RandomFRF", "h1", f"one column per channel ({len(chans)})", f"shape {frf.h1.shape}"
        )
    frf.check_drive_force(drive_force_index(chans))
    config_json = to_json(config, "config")
    setup_json = to_json(setup, "setup")
    versions = software_versions(software)

    def fill(f: h5py.File) -> None:
        write_header(
            f,
            kind=KIND_RANDOM,
            channels=chans,
            actuator=actuator,
            config_json=config_json,
            setup_json=setup_json,
            software=versions,
            exit_status="success",
        )
        g = f.create_group("frf")
        g.create_dataset("frequency", data=frf.frequency_hz)
        g.create_dataset("h1", data=frf.h1)
        g.create_dataset("coherence", data=frf.coherence)
        g.create_dataset("force_psd", data=frf.force_psd)
        g.attrs["estimator"] = frf.estimator
        g.attrs["n_averages"] = np.int64(frf.n_averages)
        g.attrs["window"] = frf.window
        g.attrs["overlap"] = frf.overlap
        g.attrs["fs"] = frf.fs_hz
        g.attrs["rms_force_n"] = frf.rms_force_n

    build_file(path, overwrite, fill)
    log.info("wrote random-excitation file %s (%d frequencies)", path, frf.frequency_hz.size)
    return path
