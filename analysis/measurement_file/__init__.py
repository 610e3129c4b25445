"""The measurement file: the one implementation of the rig/analysis contract.

The contract is ``docs/measurement-file.md``.

A run of the rig is one HDF5 file; the rig writes it with this package and analysis reads it
with this package, as must any other tool. The reader validates everything and fails with a
:class:`MeasurementFileError` naming the file, the path inside it, what was expected and what
was found.

Two compatible extensions of format_version 1 (files without them read as before):

- ``/extra_orders_num``, ``/extra_orders_den`` (E,) int64 with ``/steps/extra_force`` (n, E)
  complex128 and ``/steps/extra_force_std`` (n, E) float64: the drive force at orders the drive
  does not contain (the shaker's push-back at the response's harmonics); all four or none.
  A model driven by the measured force is driven by these too.
- ``/frf`` attribute ``estimator``: ``"H1"`` or ``"periodic"`` (the ratio of the spectra
  averaged over the periods of a periodic excitation, not biased by noise on the force).

Modules
-------
schema
    Names, allowed values, ``/steps`` layout, errors and array checks.
records
    What a writer is given: :class:`ChannelInfo`, :class:`Actuator`, :class:`StepRecord`,
    :class:`RandomFRF`.
layout
    Root attributes, ``/setup`` and atomic file creation.
writer
    :func:`create_stepped_sine`, :class:`SteppedSineWriter`, :func:`open_for_resume`.
random_writer
    :func:`write_random`.
reader
    :func:`read_measurement`, :func:`read_raw`.
h5check
    Fetching groups, datasets and attributes with contract-violation messages.
data
    What a reader returns: :class:`SteppedSineData`, :class:`RandomData`, :class:`RawRecord`.

Examples
--------
>>> with create_stepped_sine(path, channels=chans, actuator=act, levels_n=[2.0, 4.0],
...                          orders_num=[1, 2, 3], orders_den=[1, 1, 1],
...                          force_targets=targets, config={}, setup={}) as w:  # doctest: +SKIP
...     for record in run():
...         w.append_step(record)
...     w.finish("success", "")
>>> data = read_measurement(path)  # doctest: +SKIP
>>> h = data.select(level_index=0, sweep_direction=+1).frf("acc7")  # (n, H) complex
"""

from .data import RandomData, RawRecord, ResumeEvent, RunData, SteppedSineData
from .layout import OutputExistsError
from .random_writer import write_random
from .reader import read_measurement, read_raw
from .records import Actuator, ChannelInfo, RandomFRF, StepRecord
from .schema import (
    CHANNEL_FIELDS,
    DIRECTIONS,
    EXIT_STATUSES,
    FORMAT,
    FORMAT_VERSION,
    KIND_RANDOM,
    KIND_STEPPED_SINE,
    QUANTITIES,
    ROLES,
    FieldValueError,
    MeasurementFileError,
    safe_std,
)
from .status import incomplete_note, input_notes, planned_steps, require_steps, status_text
from .writer import (
    SteppedSineWriter,
    create_stepped_sine,
    note_output_not_at_zero,
    open_for_resume,
)

__all__ = [
    "CHANNEL_FIELDS",
    "DIRECTIONS",
    "EXIT_STATUSES",
    "FORMAT",
    "FORMAT_VERSION",
    "KIND_RANDOM",
    "KIND_STEPPED_SINE",
    "QUANTITIES",
    "ROLES",
    "Actuator",
    "ChannelInfo",
    "FieldValueError",
    "MeasurementFileError",
    "OutputExistsError",
    "RandomData",
    "RandomFRF",
    "RawRecord",
    "ResumeEvent",
    "RunData",
    "StepRecord",
    "SteppedSineData",
    "SteppedSineWriter",
    "create_stepped_sine",
    "incomplete_note",
    "input_notes",
    "note_output_not_at_zero",
    "open_for_resume",
    "planned_steps",
    "read_measurement",
    "read_raw",
    "require_steps",
    "safe_std",
    "status_text",
    "write_random",
]
