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
from dataclasses import dataclass
from pathlib import Path

from pydantic import Field

from analysis.model import Model, load_model
from analysis.settings import ConfigError, Integer, NonNegative, Text, build, declare, settings
from sim_backend.amplifier import AmplifierConstants
from sim_backend.shaker import ShakerConstants

__all__ = [
    "NoiseFloors",
    "SensorDefaults",
    "Truth",
    "TruthTable",
    "TRUTH_DIR",
    "list_truths",
    "load_truth",
]

logger = logging.getLogger(__name__)

TRUTH_DIR = Path(__file__).parent / "truths"


@settings()
class NoiseFloors:
    """White measurement noise of each quantity as an amplitude spectral density.

    A channel sampled at ``fs`` gets a per-sample standard deviation ``asd * sqrt(fs / 2)``.
    """

    force_n_per_rthz: NonNegative = declare("Force channels [N/sqrt(Hz)].", 0.0)
    acceleration_ms2_per_rthz: NonNegative = declare("Acceleration channels [m/s^2/sqrt(Hz)].", 0.0)
    voltage_v_per_rthz: NonNegative = declare("Voltage channels [V/sqrt(Hz)].", 0.0)

    def for_quantity(self, quantity: str) -> float:
        """Amplitude spectral density of ``quantity`` ("force", "acceleration", "voltage")."""
        return {
            "force": self.force_n_per_rthz,
            "acceleration": self.acceleration_ms2_per_rthz,
            "voltage": self.voltage_v_per_rthz,
        }[quantity]


@settings()
class SensorDefaults:
    """Sensor masses and converter resolution used unless a channel says otherwise."""

    accelerometer_mass_kg: NonNegative = declare(
        "Mass of one accelerometer with its cable end [kg] (a PCB 352A56 class sensor).", 0.0055
    )
    impedance_head_mass_kg: NonNegative = declare(
        "Mass of the impedance head below its force gauge, added at the drive point [kg].", 0.01
    )
    adc_bits: Integer = declare(
        "Resolution of the input converters over each channel's range [bits].", 16, ge=8, le=32
    )


@settings(kw_only=True)
class TruthTable:
    """The ``[truth]`` table of a truth file: what only the simulator reads."""

    description: Text = declare("What is hidden, for people.", "")
    hidden_effect: Text = declare("Short tag of the hidden effect.", "none")
    seed: Integer = declare("Default noise seed.", 0, ge=0)
    drive_point: Integer = declare(
        "Drive point used when no force channel names the drive point.", 3
    )
    noise: NoiseFloors = Field(default_factory=NoiseFloors, description="Noise floors.")
    shaker: ShakerConstants = Field(default_factory=ShakerConstants, description="The shaker.")
    amplifier: AmplifierConstants = Field(
        default_factory=AmplifierConstants, description="The power amplifier."
    )
    sensors: SensorDefaults = Field(default_factory=SensorDefaults, description="The sensors.")


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
        ``[truth]`` table, or a value in it is invalid (a :class:`~analysis.settings.ConfigError`
        naming the file and the key path, e.g. ``truth.noise.force_n_per_rthz``).
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
    if model.truth is None:
        raise ValueError(f"{source}: no [truth] table: this is an analysis model, not a truth")
    table = build(TruthTable, model.truth, source, at=("truth",))
    if table.drive_point not in model.points:
        raise ConfigError(source, ("truth", "drive_point"), f"{table.drive_point!r} is not a point")
    truth = Truth(
        name=path.stem if path.parent == TRUTH_DIR.resolve() else source,
        model=model,
        description=table.description,
        hidden_effect=table.hidden_effect,
        seed=table.seed,
        drive_point=table.drive_point,
        noise=table.noise,
        shaker=table.shaker,
        amplifier=table.amplifier,
        sensors=table.sensors,
    )
    logger.debug("loaded truth %s (%s)", truth.name, truth.hidden_effect)
    return truth
