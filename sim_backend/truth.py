"""Truth structures of the simulated rig: model files with a ``[truth]`` table.

A truth file is a model file (the schema of ``analysis/models/clearance_rig.toml``) whose
parameter ``value`` s are the simulated reality, plus a ``[truth]`` table that only the
simulator reads (``analysis.model.load_model`` refuses such a file unless
``allow_truth=True``)::

    [truth]
    description = "..."           # what is hidden, for people
    hidden_effect = "none"        # short tag
    seed = 20160919               # default noise seed
    drive_point = 3               # used when no force channel names the drive point

    [truth.noise]                 # white noise amplitude spectral densities per quantity
    force_n_per_rthz = 1e-2
    acceleration_ms2_per_rthz = 2e-2
    voltage_v_per_rthz = 1e-5

    [truth.shaker]                # sim_backend.shaker.ShakerConstants fields
    [truth.amplifier]             # sim_backend.amplifier.AmplifierConstants fields
    [truth.sensors]               # default sensor masses [kg], ADC resolution
    accelerometer_mass_kg = 0.0055
    impedance_head_mass_kg = 0.01
    adc_bits = 16

The shipped truths live in ``sim_backend/truths/*.toml``; :func:`load_truth` finds them by name
or reads any path.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from analysis.model import Model, load_model
from sim_backend.amplifier import AmplifierConstants
from sim_backend.shaker import ShakerConstants

__all__ = ["NoiseFloors", "SensorDefaults", "Truth", "TRUTH_DIR", "list_truths", "load_truth"]

logger = logging.getLogger(__name__)

TRUTH_DIR = Path(__file__).parent / "truths"
_TRUTH_KEYS = {
    "description",
    "hidden_effect",
    "seed",
    "drive_point",
    "noise",
    "shaker",
    "amplifier",
    "sensors",
}


def _positive_fields(obj: object, owner: str, allow_zero: bool) -> None:
    for f in fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        if f.type in ("int", int):
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise TypeError(f"{owner}.{f.name}: expected a number, got {value!r}")
        ok = math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
        if not ok:
            raise ValueError(
                f"{owner}.{f.name}: must be finite and {'>= 0' if allow_zero else '> 0'}, "
                f"got {value!r}"
            )
        object.__setattr__(obj, f.name, float(value))


@dataclass(frozen=True)
class NoiseFloors:
    """White measurement noise of each quantity as an amplitude spectral density.

    A channel sampled at ``fs`` gets a per-sample standard deviation ``asd * sqrt(fs / 2)``.

    Parameters
    ----------
    force_n_per_rthz : float
        Force channels [N/sqrt(Hz)], >= 0.
    acceleration_ms2_per_rthz : float
        Acceleration channels [m/s^2/sqrt(Hz)], >= 0.
    voltage_v_per_rthz : float
        Voltage channels [V/sqrt(Hz)], >= 0.
    """

    force_n_per_rthz: float = 0.0
    acceleration_ms2_per_rthz: float = 0.0
    voltage_v_per_rthz: float = 0.0

    def __post_init__(self) -> None:
        _positive_fields(self, "NoiseFloors", allow_zero=True)

    def for_quantity(self, quantity: str) -> float:
        """Amplitude spectral density of ``quantity`` ("force", "acceleration", "voltage")."""
        return {
            "force": self.force_n_per_rthz,
            "acceleration": self.acceleration_ms2_per_rthz,
            "voltage": self.voltage_v_per_rthz,
        }[quantity]


@dataclass(frozen=True)
class SensorDefaults:
    """Sensor masses and converter resolution used unless a channel says otherwise.

    Parameters
    ----------
    accelerometer_mass_kg : float
        Mass of one accelerometer with its cable end [kg] (a PCB 352A56 class sensor).
    impedance_head_mass_kg : float
        Mass of the impedance head below its force gauge, added at the drive point [kg].
    adc_bits : int
        Resolution of the input converters over each channel's range.
    """

    accelerometer_mass_kg: float = 0.0055
    impedance_head_mass_kg: float = 0.01
    adc_bits: int = 16

    def __post_init__(self) -> None:
        _positive_fields(self, "SensorDefaults", allow_zero=True)
        if isinstance(self.adc_bits, bool) or not isinstance(self.adc_bits, int):
            raise TypeError(f"SensorDefaults.adc_bits: expected an int, got {self.adc_bits!r}")
        if not 8 <= self.adc_bits <= 32:
            raise ValueError(f"SensorDefaults.adc_bits: must be in [8, 32], got {self.adc_bits}")


@dataclass(frozen=True)
class Truth:
    """A loaded truth structure.

    Attributes
    ----------
    name : str
        File stem (``"reference"``) or the path given.
    model : Model
        The structure as it really is (parameter values are the truth); ``model.truth`` holds
        the raw ``[truth]`` table.
    description, hidden_effect : str
    seed : int
        Default noise seed.
    drive_point : int
        Drive point when no force channel is configured.
    noise : NoiseFloors
    shaker : ShakerConstants
    amplifier : AmplifierConstants
    sensors : SensorDefaults
    """

    name: str
    model: Model
    description: str
    hidden_effect: str
    seed: int
    drive_point: int
    noise: NoiseFloors
    shaker: ShakerConstants
    amplifier: AmplifierConstants
    sensors: SensorDefaults


def list_truths() -> list[str]:
    """Names of the shipped truth structures, sorted."""
    return sorted(p.stem for p in TRUTH_DIR.glob("*.toml"))


def _table(raw: dict, key: str, source: str) -> dict[str, Any]:
    value = raw.get(key, {})
    if not isinstance(value, dict):
        raise ValueError(f"{source}: truth.{key}: expected a table, got {value!r}")
    return value


def _build(cls: type, raw: dict, key: str, source: str) -> Any:
    try:
        return cls(**_table(raw, key, source))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: truth.{key}: {exc}") from None


def load_truth(name_or_path: str | Path = "reference") -> Truth:
    """Load a truth structure by name (see :func:`list_truths`) or from a path.

    Parameters
    ----------
    name_or_path : str or Path
        A shipped truth's name, or the path of a truth file.

    Returns
    -------
    Truth

    Raises
    ------
    ValueError
        If the name is unknown (the message lists the shipped ones), the file has no
        ``[truth]`` table, or a value in it is invalid (the message names the key).
    """
    path = Path(name_or_path)
    if not path.suffix and not path.exists():
        path = TRUTH_DIR / f"{name_or_path}.toml"
        if not path.exists():
            raise ValueError(
                f"unknown truth structure {str(name_or_path)!r}; shipped: {list_truths()}"
            )
    path = path.resolve()
    return _load(path, path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=32)
def _load(path: Path, mtime_ns: int) -> Truth:
    """Read a truth file (cached per path and modification time; a Truth is immutable)."""
    import sim_backend.hysteresis  # noqa: F401  (registers the simulator-only element kinds)

    model = load_model(path, allow_truth=True)
    source = str(path)
    raw = model.truth
    if raw is None:
        raise ValueError(f"{source}: no [truth] table: this is an analysis model, not a truth")
    unknown = set(raw) - _TRUTH_KEYS
    if unknown:
        raise ValueError(f"{source}: truth: unknown key(s) {sorted(unknown)}")
    drive_point = raw.get("drive_point", 3)
    if drive_point not in model.points:
        raise ValueError(f"{source}: truth.drive_point: {drive_point!r} is not a point")
    seed = raw.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"{source}: truth.seed: expected an integer >= 0, got {seed!r}")
    truth = Truth(
        name=path.stem if path.parent == TRUTH_DIR.resolve() else source,
        model=model,
        description=str(raw.get("description", "")),
        hidden_effect=str(raw.get("hidden_effect", "none")),
        seed=seed,
        drive_point=int(drive_point),
        noise=_build(NoiseFloors, raw, "noise", source),
        shaker=_build(ShakerConstants, raw, "shaker", source),
        amplifier=_build(AmplifierConstants, raw, "amplifier", source),
        sensors=_build(SensorDefaults, raw, "sensors", source),
    )
    logger.debug("loaded truth %s (%s)", truth.name, truth.hidden_effect)
    return truth
