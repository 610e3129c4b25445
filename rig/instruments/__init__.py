"""Serial instruments of the rig: a small SCPI layer and the power-amplifier driver."""

from rig.instruments.amplifier import AmplifierStatus, PowerAmplifier
from rig.instruments.scpi import (
    InstrumentError,
    InstrumentIdentity,
    InstrumentReplyError,
    InstrumentTimeout,
    ScpiError,
    ScpiInstrument,
)

__all__ = [
    "AmplifierStatus",
    "InstrumentError",
    "InstrumentIdentity",
    "InstrumentReplyError",
    "InstrumentTimeout",
    "PowerAmplifier",
    "ScpiError",
    "ScpiInstrument",
]
