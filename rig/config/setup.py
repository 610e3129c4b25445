"""The lab setup: DAQ, drive chain and sensors, kept apart from the test plans.

A setup describes what is on the bench (which sensor sits where, with which sensitivity,
serial number and calibration date; the DAQ's clock and channels; the amplifier's serial port);
a plan (:mod:`rig.config.plans`) says what to do with it and names the setup it expects. Setups are
TOML files; the built-in ``reference`` setup (``rig/setups/reference.toml``) is the paper's rig.
Every setting is a frozen dataclass validated on construction; loading a file reports the file
and the key of any problem.

Layout of a setup file::

    name = "reference"
    description = "..."

    [daq]                       # DaqSetup
    device = "cDAQ1"
    sample_rate_hz = 25600.0

    [drive]                     # DriveSetup: the AO channel to the amplifier and the drive point
    physical = "cDAQ1Mod5/ao0"
    limit_v = 5.0
    point = 3
    direction = "y"

    [amplifier]                 # AmplifierSetup (port optional: no remote control without it)
    model = "..."

    [[channels]]                # ChannelSetup, one per acquired channel, in acquisition order
    name = "force3"
    ...
"""

from __future__ import annotations

import dataclasses
import datetime
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from analysis.measurement_file import Actuator, ChannelInfo
from rig.backends.protocol import AcquisitionConfig, AIChannelConfig, AOChannelConfig
from rig.config.tomlconfig import ConfigError, Table, read_toml

__all__ = [
    "AmplifierSetup",
    "ChannelSetup",
    "DaqSetup",
    "DriveSetup",
    "LabSetup",
    "builtin_setups",
    "load_setup",
    "setup_from_dict",
]

QUANTITY_UNITS = {"force": "N", "acceleration": "m/s^2", "voltage": "V"}
SENSITIVITY_UNITS = {"force": "mV/N", "acceleration": "mV/g", "voltage": "V/V"}
ROLES = ("drive-force", "drive-acceleration", "response", "reference")
AXES = ("x", "y", "z")


def _check_positive(owner: str, name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{owner}.{name}: expected a number, got {value!r}")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{owner}.{name}: must be finite and > 0, got {value!r}")


def _check_direction(owner: str, value: str) -> None:
    if not isinstance(value, str) or value.lstrip("-") not in AXES or value.count("-") > 1:
        raise ValueError(
            f"{owner}.direction: expected x, y or z (with a leading '-' for a reversed axis), "
            f"got {value!r}"
        )


@dataclass(frozen=True)
class ChannelSetup:
    """One acquired channel and the sensor on it.

    Parameters
    ----------
    name : str
        Unique channel name (the name in the measurement file).
    physical : str
        DAQ channel, e.g. ``"cDAQ1Mod1/ai0"``.
    quantity : {"force", "acceleration", "voltage"}
        What the channel measures; data are in N, m/s^2 or V.
    point : int
        Measurement point the sensor sits on (0 for a voltage channel).
    direction : str
        Sensor axis, ``"x"``, ``"y"`` or ``"z"`` (``"-y"``: mounted reversed).
    sensitivity : float
        Sensor sensitivity in ``sensitivity_unit`` (mV/N, mV/g or V/V).
    sensitivity_unit : str
        ``"mV/N"`` for force, ``"mV/g"`` for acceleration, ``"V/V"`` for voltage.
    range_v : float
        Input range of the ADC [V] (symmetric).
    output_swing_v : float
        The sensor's output swing [V] from its data sheet (a 10 mV/g accelerometer rated
        +-500 g swings +-5 V); 0 when not known, the input range is then taken to hold it. The
        saturation check (:mod:`rig.run.safety`) judges a flat-topped waveform against the smaller
        of the two.
    role : {"drive-force", "drive-acceleration", "response", "reference"}
        ``drive-force``: the force gauge at the drive point (exactly one per setup).
    iepe : bool
        Powered by constant-current (IEPE) excitation, AC coupled.
    model, serial : str
        Sensor model and serial number.
    calibration_date : str
        Date of the sensor's last calibration, ISO ``YYYY-MM-DD`` (empty if unknown).
    mass_kg : float
        Sensor mass added to the structure at ``point`` [kg] (0 when already counted, e.g.
        the acceleration half of an impedance head).
    """

    name: str
    physical: str
    quantity: str
    point: int
    direction: str
    sensitivity: float
    sensitivity_unit: str
    range_v: float = 5.0
    output_swing_v: float = 0.0
    role: str = "response"
    iepe: bool = True
    model: str = ""
    serial: str = ""
    calibration_date: str = ""
    mass_kg: float = 0.0

    def __post_init__(self) -> None:
        owner = f"ChannelSetup {self.name!r}"
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"ChannelSetup.name: expected a non-empty string, got {self.name!r}")
        if not isinstance(self.physical, str) or not self.physical.strip():
            raise ValueError(f"{owner}.physical: expected a DAQ channel like 'Dev1/ai0'")
        if self.quantity not in QUANTITY_UNITS:
            raise ValueError(
                f"{owner}.quantity: expected one of {tuple(QUANTITY_UNITS)}, got {self.quantity!r}"
            )
        if isinstance(self.point, bool) or not isinstance(self.point, int) or self.point < 0:
            raise ValueError(f"{owner}.point: expected an integer >= 0, got {self.point!r}")
        _check_direction(owner, self.direction)
        _check_positive(owner, "sensitivity", self.sensitivity)
        expected = SENSITIVITY_UNITS[self.quantity]
        if self.sensitivity_unit != expected:
            raise ValueError(
                f"{owner}.sensitivity_unit: a {self.quantity} channel needs {expected!r}, "
                f"got {self.sensitivity_unit!r}"
            )
        _check_positive(owner, "range_v", self.range_v)
        if not (math.isfinite(self.output_swing_v) and self.output_swing_v >= 0):
            raise ValueError(
                f"{owner}.output_swing_v: must be >= 0 (0: not known), got {self.output_swing_v!r}"
            )
        if self.role not in ROLES:
            raise ValueError(f"{owner}.role: expected one of {ROLES}, got {self.role!r}")
        if self.role == "drive-force" and self.quantity != "force":
            raise ValueError(f"{owner}.role: a 'drive-force' channel must measure force")
        if self.calibration_date:
            try:
                datetime.date.fromisoformat(self.calibration_date)
            except (TypeError, ValueError):
                raise ValueError(
                    f"{owner}.calibration_date: expected YYYY-MM-DD, got {self.calibration_date!r}"
                ) from None
        if not (math.isfinite(self.mass_kg) and self.mass_kg >= 0):
            raise ValueError(f"{owner}.mass_kg: must be >= 0, got {self.mass_kg!r}")
        object.__setattr__(self, "sensitivity", float(self.sensitivity))
        object.__setattr__(self, "range_v", float(self.range_v))
        object.__setattr__(self, "output_swing_v", float(self.output_swing_v))
        object.__setattr__(self, "mass_kg", float(self.mass_kg))

    @property
    def unit(self) -> str:
        """SI unit of the data (N, m/s^2, V)."""
        return QUANTITY_UNITS[self.quantity]

    @property
    def units_per_volt(self) -> float:
        """Physical units per sensor volt (to turn the ADC range into channel units)."""
        if self.quantity == "force":
            return 1000.0 / self.sensitivity
        if self.quantity == "acceleration":
            return 1000.0 / self.sensitivity * 9.80665
        return 1.0 / self.sensitivity

    @property
    def range_units(self) -> float:
        """Input range in channel units (N, m/s^2, V)."""
        return self.range_v * self.units_per_volt

    @property
    def full_scale_units(self) -> float:
        """Where the signal chain saturates, in channel units: the smaller of the sensor's
        output swing (when known) and the input range."""
        swing = self.output_swing_v if self.output_swing_v > 0 else self.range_v
        return min(swing, self.range_v) * self.units_per_volt

    def ai_config(self) -> AIChannelConfig:
        """The DAQ input channel."""
        return AIChannelConfig(
            name=self.name,
            physical=self.physical,
            quantity=self.quantity,
            sensitivity=self.sensitivity,
            sensitivity_unit=self.sensitivity_unit,
            range_v=self.range_v,
            iepe=self.iepe,
            point=self.point,
            direction=self.direction,
        )

    def channel_info(self) -> ChannelInfo:
        """The row of the measurement file's channel table."""
        return ChannelInfo(
            name=self.name,
            point=self.point,
            direction=self.direction,
            quantity=self.quantity,
            unit=self.unit,
            sensitivity=self.sensitivity,
            sensitivity_unit=self.sensitivity_unit,
            role=self.role,
            mass_kg=self.mass_kg,
            serial=self.serial,
        )


@dataclass(frozen=True)
class DaqSetup:
    """The acquisition device.

    Parameters
    ----------
    device : str
        NI device (or cDAQ chassis) name; also the name the device lock uses.
    sample_rate_hz : float
        Sample rate of output and inputs [Hz] (a plan may ask for another).
    buffer_s : float
        Input buffer length [s].
    watchdog_s : float
        Hardware watchdog timeout of the drive output [s] where the device has one.
    """

    device: str = "Dev1"
    sample_rate_hz: float = 25600.0
    buffer_s: float = 10.0
    watchdog_s: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.device, str) or not self.device.strip():
            raise ValueError(f"DaqSetup.device: expected a device name, got {self.device!r}")
        for name in ("sample_rate_hz", "buffer_s", "watchdog_s"):
            _check_positive("DaqSetup", name, getattr(self, name))


@dataclass(frozen=True)
class DriveSetup:
    """The drive output and where the shaker pushes.

    Parameters
    ----------
    physical : str
        AO channel to the amplifier input.
    limit_v : float
        Hard output limit of the AO channel [V]; plans set their own, lower, drive limit.
    point : int
        Measurement point of the shaker (the actuator).
    direction : str
        Direction the shaker pushes.
    shaker : str
        Shaker and stinger, for the record.
    static_stiffness_n_per_m : float
        Stiffness with which the shaker holds the drive point at its mean position: the
        armature suspension in series with the stinger [N/m] (0: unknown or negligible). It
        goes into the measurement file (the mean force is not measured) so that a model can
        place the mean response of a structure with a one-sided contact.
    """

    physical: str = "Dev1/ao0"
    limit_v: float = 5.0
    point: int = 3
    direction: str = "y"
    shaker: str = ""
    static_stiffness_n_per_m: float = 0.0

    def __post_init__(self) -> None:
        _check_positive("DriveSetup", "limit_v", self.limit_v)
        if self.limit_v > 10:
            raise ValueError(f"DriveSetup.limit_v: at most 10 V, got {self.limit_v}")
        if isinstance(self.point, bool) or not isinstance(self.point, int) or self.point < 0:
            raise ValueError(f"DriveSetup.point: expected an integer >= 0, got {self.point!r}")
        _check_direction("DriveSetup", self.direction)
        k = self.static_stiffness_n_per_m
        if isinstance(k, bool) or not isinstance(k, int | float) or not (0 <= k < float("inf")):
            raise ValueError(
                f"DriveSetup.static_stiffness_n_per_m: expected a number >= 0 N/m, got {k!r}"
            )


@dataclass(frozen=True)
class AmplifierSetup:
    """The power amplifier.

    Parameters
    ----------
    port : str
        Serial port (or pyserial URL) of its remote interface; empty: not remote controlled
        (overloads are then seen only as a lost drive force).
    gain_v_per_v : float
        Gain to set at the start of a run [V/V]; 0 leaves the amplifier's gain as it is.
    model, serial : str
        For the record.
    timeout_s : float
        Reply timeout of the serial interface [s].
    """

    port: str = ""
    gain_v_per_v: float = 0.0
    model: str = ""
    serial: str = ""
    timeout_s: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gain_v_per_v) and self.gain_v_per_v >= 0):
            raise ValueError(f"AmplifierSetup.gain_v_per_v: must be >= 0, got {self.gain_v_per_v}")
        _check_positive("AmplifierSetup", "timeout_s", self.timeout_s)


@dataclass(frozen=True)
class LabSetup:
    """Everything on the bench.

    Parameters
    ----------
    name : str
    description : str
    daq : DaqSetup
    drive : DriveSetup
    amplifier : AmplifierSetup
    channels : tuple of ChannelSetup
        Every channel that can be acquired, in acquisition order; exactly one of role
        ``"drive-force"``, at the drive point.
    """

    name: str
    description: str
    daq: DaqSetup
    drive: DriveSetup
    amplifier: AmplifierSetup
    channels: tuple[ChannelSetup, ...]

    def __post_init__(self) -> None:
        chans = tuple(self.channels)
        if not chans:
            raise ValueError("LabSetup.channels: at least one channel is needed")
        names = [c.name for c in chans]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"LabSetup.channels: duplicate channel names {dup}")
        phys = [c.physical for c in chans]
        dup = sorted({p for p in phys if phys.count(p) > 1})
        if dup:
            raise ValueError(f"LabSetup.channels: physical channels used twice {dup}")
        drive = [c for c in chans if c.role == "drive-force"]
        if len(drive) != 1:
            raise ValueError(
                "LabSetup.channels: exactly one channel of role 'drive-force' is needed, got "
                f"{[c.name for c in drive] or 'none'}"
            )
        if drive[0].point != self.drive.point:
            raise ValueError(
                f"LabSetup.channels: the drive-force channel {drive[0].name!r} is at point "
                f"{drive[0].point}, the drive at point {self.drive.point}"
            )
        object.__setattr__(self, "channels", chans)

    # -- channel selection ----------------------------------------------------------------------
    @property
    def drive_force_channel(self) -> ChannelSetup:
        """The force gauge at the drive point."""
        return next(c for c in self.channels if c.role == "drive-force")

    @property
    def points(self) -> tuple[int, ...]:
        """Points that carry an accelerometer, ascending."""
        return tuple(sorted({c.point for c in self.channels if c.quantity == "acceleration"}))

    def channels_for_points(self, points: Iterable[int]) -> tuple[ChannelSetup, ...]:
        """The drive-force channel and the acceleration channels at ``points``.

        Parameters
        ----------
        points : iterable of int
            Measurement points to record (the drive point's acceleration is the impedance
            head's).

        Returns
        -------
        tuple of ChannelSetup
            In the setup's acquisition order.

        Raises
        ------
        ValueError
            If a point has no acceleration channel (the message lists those that do).
        """
        wanted = [int(p) for p in points]
        have = set(self.points)
        missing = [p for p in wanted if p not in have]
        if missing:
            raise ValueError(
                f"setup {self.name!r} has no accelerometer at point(s) {missing}; "
                f"points with one: {list(self.points)}"
            )
        return tuple(
            c
            for c in self.channels
            if c.role == "drive-force" or (c.quantity == "acceleration" and c.point in wanted)
        )

    def acquisition_config(
        self, channels: Iterable[ChannelSetup], sample_rate_hz: float | None = None
    ) -> AcquisitionConfig:
        """The backend configuration for a channel selection."""
        return AcquisitionConfig(
            sample_rate_hz=float(sample_rate_hz or self.daq.sample_rate_hz),
            ao=AOChannelConfig(self.drive.physical, self.drive.limit_v),
            ai=tuple(c.ai_config() for c in channels),
            buffer_s=self.daq.buffer_s,
            watchdog_s=self.daq.watchdog_s,
        )

    @property
    def actuator(self) -> Actuator:
        """Where the shaker acts (the file's ``/setup/actuator``)."""
        return Actuator(
            self.drive.point, self.drive.direction, float(self.drive.static_stiffness_n_per_m)
        )

    def sensor_masses_kg(self, channels: Iterable[ChannelSetup] | None = None) -> dict[str, float]:
        """Sensor mass per channel name (what a simulated rig adds to its structure)."""
        return {c.name: c.mass_kg for c in (self.channels if channels is None else channels)}

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the file's ``setup_json``; :func:`setup_from_dict` reads it back)."""
        return {
            "name": self.name,
            "description": self.description,
            "daq": dataclasses.asdict(self.daq),
            "drive": dataclasses.asdict(self.drive),
            "amplifier": dataclasses.asdict(self.amplifier),
            "channels": [dataclasses.asdict(c) for c in self.channels],
        }

    def with_sample_rate(self, sample_rate_hz: float) -> LabSetup:
        """The same setup at another sample rate."""
        return dataclasses.replace(
            self, daq=dataclasses.replace(self.daq, sample_rate_hz=float(sample_rate_hz))
        )


_CHANNEL_KEYS = {
    "name": ("text", ...),
    "physical": ("text", ...),
    "quantity": ("text", ...),
    "point": ("integer", 0),
    "direction": ("text", "y"),
    "sensitivity": ("number", ...),
    "sensitivity_unit": ("text", ...),
    "range_v": ("number", 5.0),
    "output_swing_v": ("number", 0.0),
    "role": ("text", "response"),
    "iepe": ("flag", True),
    "model": ("text", ""),
    "serial": ("text", ""),
    "calibration_date": ("text", ""),
    "mass_kg": ("number", 0.0),
}


def _channel(table: Table) -> ChannelSetup:
    kwargs: dict[str, Any] = {}
    for key, (kind, default) in _CHANNEL_KEYS.items():
        getter = getattr(table, kind)
        if key == "calibration_date" and isinstance(table.raw(key, ""), datetime.date):
            kwargs[key] = table.raw(key).isoformat()  # a TOML date
            continue
        kwargs[key] = getter(key) if default is ... else getter(key, default)
    table.finish()
    return table.build(ChannelSetup, **kwargs)


def setup_from_dict(data: Mapping[str, Any], source: str = "setup") -> LabSetup:
    """Build and validate a setup from parsed TOML or :meth:`LabSetup.to_dict` output.

    Raises
    ------
    ConfigError
        Naming ``source`` and the key of the first problem.
    """
    root = Table(data, source)
    name = root.text("name")
    description = root.text("description", "")
    daq_t = root.table("daq")
    daq = daq_t.build(
        DaqSetup,
        device=daq_t.text("device", "Dev1"),
        sample_rate_hz=daq_t.number("sample_rate_hz", 25600.0, positive=True),
        buffer_s=daq_t.number("buffer_s", 10.0, positive=True),
        watchdog_s=daq_t.number("watchdog_s", 1.0, positive=True),
    )
    daq_t.finish()
    drive_t = root.table("drive", required=True)
    drive = drive_t.build(
        DriveSetup,
        physical=drive_t.text("physical"),
        limit_v=drive_t.number("limit_v", positive=True),
        point=drive_t.integer("point", minimum=0),
        direction=drive_t.text("direction", "y"),
        shaker=drive_t.text("shaker", ""),
        static_stiffness_n_per_m=drive_t.number("static_stiffness_n_per_m", 0.0, minimum=0.0),
    )
    drive_t.finish()
    amp_t = root.table("amplifier")
    amplifier = amp_t.build(
        AmplifierSetup,
        port=amp_t.text("port", ""),
        gain_v_per_v=amp_t.number("gain_v_per_v", 0.0, minimum=0.0),
        model=amp_t.text("model", ""),
        serial=amp_t.text("serial", ""),
        timeout_s=amp_t.number("timeout_s", 1.0, positive=True),
    )
    amp_t.finish()
    channels = tuple(_channel(t) for t in root.tables("channels", required=True))
    root.finish()
    return root.build(
        LabSetup,
        key="channels",
        name=name,
        description=description,
        daq=daq,
        drive=drive,
        amplifier=amplifier,
        channels=channels,
    )


def builtin_setups() -> dict[str, Path]:
    """Name -> file of the setups shipped in ``rig/setups``."""
    folder = resources.files("rig") / "setups"
    return {Path(str(p)).stem: Path(str(p)) for p in folder.iterdir() if p.name.endswith(".toml")}


def load_setup(name_or_path: str | Path) -> LabSetup:
    """Load a built-in setup by name or a setup file by path.

    Raises
    ------
    ConfigError
        If the name is unknown (the message lists the built-in ones), the file cannot be read,
        or a setting is invalid (the message names the file and the key).
    """
    text = str(name_or_path)
    builtins = builtin_setups()
    if text in builtins:
        path, label = builtins[text], f"setup {text!r} ({builtins[text]})"
    else:
        path = Path(text)
        if not path.exists():
            raise ConfigError(
                f"setup {text!r}: no such file and not a built-in setup "
                f"(built-in: {', '.join(sorted(builtins))})"
            )
        label = f"setup file {path}"
    return setup_from_dict(read_toml(path, label), label)
