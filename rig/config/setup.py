"""The lab setup: DAQ, drive chain and sensors, kept apart from the test plans.

A setup describes what is on the bench (which sensor sits where, with which sensitivity,
serial number and calibration date; the DAQ's clock and channels; the amplifier's serial port);
a plan (:mod:`rig.config.plans`) says what to do with it and names the setup it expects. Setups are
TOML files; the built-in ``reference`` setup (``rig/setups/reference.toml``) is the paper's rig.
Every setting is declared once (:mod:`rig.config.settings`) in a frozen dataclass validated on
construction; loading a file reports the file and the key path of any problem.

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
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import AfterValidator, BeforeValidator, Field

from analysis.measurement_file import Actuator, ChannelInfo
from rig.backends.protocol import AcquisitionConfig, AIChannelConfig, AOChannelConfig
from rig.config.settings import (
    Flag,
    Integer,
    NonNegative,
    Positive,
    SettingError,
    Text,
    build,
    dump,
    settings,
)
from rig.config.settings import declare as _doc
from rig.config.tomlconfig import builtin_files, read_named

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
Quantity = Literal["force", "acceleration", "voltage"]
Role = Literal["drive-force", "drive-acceleration", "response", "reference"]
ROLES: tuple[str, ...] = get_args(Role)
AXES = ("x", "y", "z")


def _direction(value: str) -> str:
    if value.lstrip("-") not in AXES or value.count("-") > 1:
        raise ValueError(
            f"expected x, y or z (with a leading '-' for a reversed axis), got {value!r}"
        )
    return value


def _iso_date(value: object) -> object:
    return value.isoformat() if isinstance(value, datetime.date) else value  # a TOML date


def _check_date(value: str) -> str:
    if value:
        try:
            datetime.date.fromisoformat(value)
        except ValueError:
            raise ValueError(f"expected YYYY-MM-DD, got {value!r}") from None
    return value


Name = Annotated[Text, Field(min_length=1, pattern=r"\S")]
Axis = Annotated[Text, AfterValidator(_direction)]


@settings(kw_only=True)
class ChannelSetup:
    """One acquired channel and the sensor on it."""

    name: Name = _doc("Unique channel name (the name in the measurement file).")
    physical: Name = _doc('DAQ channel, e.g. "cDAQ1Mod1/ai0".')
    quantity: Quantity = _doc("What the channel measures; data are in N, m/s^2 or V.")
    point: Integer = _doc(
        "Measurement point the sensor sits on (0 for a voltage channel).", 0, ge=0
    )
    direction: Axis = _doc('Sensor axis, "x", "y" or "z" ("-y": mounted reversed).', "y")
    sensitivity: Positive = _doc("Sensor sensitivity in sensitivity_unit (mV/N, mV/g or V/V).")
    sensitivity_unit: Text = _doc('"mV/N" for force, "mV/g" for acceleration, "V/V" for voltage.')
    range_v: Positive = _doc("Input range of the ADC [V] (symmetric).", 5.0)
    output_swing_v: NonNegative = _doc(
        "The sensor's output swing [V] from its data sheet (a 10 mV/g accelerometer rated "
        "+-500 g swings +-5 V); 0 when not known, the input range is then taken to hold it. "
        "The saturation check judges a flat-topped waveform against the smaller of the two.",
        0.0,
    )
    role: Role = _doc(
        "drive-force: the force gauge at the drive point (exactly one per setup).", "response"
    )
    iepe: Flag = _doc("Powered by constant-current (IEPE) excitation, AC coupled.", True)
    model: Text = _doc("Sensor model.", "")
    serial: Text = _doc("Sensor serial number.", "")
    calibration_date: Annotated[Text, BeforeValidator(_iso_date), AfterValidator(_check_date)] = (
        _doc("Date of the sensor's last calibration, YYYY-MM-DD (empty if unknown).", "")
    )
    mass_kg: NonNegative = _doc(
        "Sensor mass added to the structure at point [kg] (0 when already counted, e.g. the "
        "acceleration half of an impedance head).",
        0.0,
    )

    def __post_init__(self) -> None:
        expected = SENSITIVITY_UNITS[self.quantity]
        if self.sensitivity_unit != expected:
            raise SettingError(
                ("sensitivity_unit",),
                f"a {self.quantity} channel needs {expected!r}, got {self.sensitivity_unit!r}",
            )
        if self.role == "drive-force" and self.quantity != "force":
            raise SettingError(("role",), "a 'drive-force' channel must measure force")

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


@settings()
class DaqSetup:
    """The acquisition device."""

    device: Name = _doc(
        "NI device (or cDAQ chassis) name; also the name the device lock uses.", "Dev1"
    )
    sample_rate_hz: Positive = _doc(
        "Sample rate of output and inputs [Hz] (a plan may ask for another).", 25600.0
    )
    buffer_s: Positive = _doc("Input buffer length [s].", 10.0)
    watchdog_s: Positive = _doc(
        "Hardware watchdog timeout of the drive output [s] where the device has one.", 1.0
    )


@settings(kw_only=True)
class DriveSetup:
    """The drive output and where the shaker pushes."""

    physical: Text = _doc("AO channel to the amplifier input.")
    limit_v: Positive = _doc(
        "Hard output limit of the AO channel [V]; plans set their own, lower, drive limit.",
        le=10,
    )
    point: Integer = _doc("Measurement point of the shaker (the actuator).", ge=0)
    direction: Axis = _doc("Direction the shaker pushes.", "y")
    shaker: Text = _doc("Shaker and stinger, for the record.", "")
    static_stiffness_n_per_m: NonNegative = _doc(
        "Stiffness with which the shaker holds the drive point at its mean position: the "
        "armature suspension in series with the stinger [N/m] (0: unknown or negligible); it "
        "goes into the measurement file (the mean force is not measured) so that a model can "
        "place the mean response of a structure with a one-sided contact.",
        0.0,
    )
    armature_mass_kg: NonNegative = _doc(
        "Moving mass of the shaker's armature and coil [kg] (0: unknown). With the force "
        "constant it gives the coil current a force and a drive-point acceleration need, "
        "(F + m a) / Bl: near a resonance of the drive point the armature's inertia, not the "
        "force, sets the current.",
        0.0,
    )
    force_constant_n_per_a: NonNegative = _doc(
        "Force constant Bl of the shaker's coil [N/A] (0: unknown).", 0.0
    )


@settings()
class AmplifierSetup:
    """The power amplifier."""

    port: Text = _doc(
        "Serial port (or pyserial URL) of its remote interface; empty: not remote controlled "
        "(overloads are then seen only as a lost drive force).",
        "",
    )
    gain_v_per_v: NonNegative = _doc(
        "Gain to set at the start of a run [V/V]; 0 leaves the amplifier's gain as it is.", 0.0
    )
    model: Text = _doc("Amplifier model, for the record.", "")
    serial: Text = _doc("Amplifier serial number, for the record.", "")
    timeout_s: Positive = _doc("Reply timeout of the serial interface [s].", 1.0)
    current_limit_a: NonNegative = _doc(
        "Peak output current at which the amplifier's overload protection switches the output "
        "off [A] (0: unknown).",
        0.0,
    )


@settings(kw_only=True)
class LabSetup:
    """Everything on the bench (the file layout is in the module's docstring)."""

    name: Text = _doc("Name of the setup.")
    description: Text = _doc("What the setup is.", "")
    daq: DaqSetup = _doc("The acquisition device.", default_factory=DaqSetup)
    drive: DriveSetup = _doc("The drive output and the drive point.")
    amplifier: AmplifierSetup = _doc("The power amplifier.", default_factory=AmplifierSetup)
    channels: tuple[ChannelSetup, ...] = _doc(
        "Every channel that can be acquired, in acquisition order; exactly one of role "
        "'drive-force', at the drive point.",
        min_length=1,
    )

    def __post_init__(self) -> None:
        chans = self.channels
        names = [c.name for c in chans]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise SettingError(("channels",), f"duplicate channel names {dup}")
        phys = [c.physical for c in chans]
        dup = sorted({p for p in phys if phys.count(p) > 1})
        if dup:
            raise SettingError(("channels",), f"physical channels used twice {dup}")
        drive = [c for c in chans if c.role == "drive-force"]
        if len(drive) != 1:
            raise SettingError(
                ("channels",),
                "exactly one channel of role 'drive-force' is needed, got "
                f"{[c.name for c in drive] or 'none'}",
            )
        if drive[0].point != self.drive.point:
            raise SettingError(
                ("channels",),
                f"the drive-force channel {drive[0].name!r} is at point {drive[0].point}, the "
                f"drive at point {self.drive.point}",
            )

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
        return dump(self)

    def with_sample_rate(self, sample_rate_hz: float) -> LabSetup:
        """The same setup at another sample rate."""
        return dataclasses.replace(
            self, daq=dataclasses.replace(self.daq, sample_rate_hz=float(sample_rate_hz))
        )


def setup_from_dict(data: Mapping[str, Any], source: str = "setup") -> LabSetup:
    """Build and validate a setup from parsed TOML or :meth:`LabSetup.to_dict` output.

    Raises
    ------
    ConfigError
        Naming ``source`` and the key of the first problem (:attr:`ConfigError.path`).
    """
    return build(LabSetup, data, source)


def builtin_setups() -> dict[str, Path]:
    """Name -> file of the setups shipped in ``rig/setups``."""
    return builtin_files("setups")


def load_setup(name_or_path: str | Path) -> LabSetup:
    """Load a built-in setup by name or a setup file by path.

    Raises
    ------
    ConfigError
        If the name is unknown (the message lists the built-in ones), the file cannot be read,
        or a setting is invalid (the message names the file and the key).
    """
    return setup_from_dict(*read_named("setup", name_or_path, builtin_setups()))
