"""What reading a measurement file gives: :class:`SteppedSineData`, :class:`RandomData`, raw blocks.

The objects are frozen and their arrays read-only; they hold only validated data (the first
``n_complete`` steps of a stepped-sine file).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from .records import Actuator, ChannelInfo
from .schema import step_fields

__all__ = ["RandomData", "RawRecord", "ResumeEvent", "RunData", "SteppedSineData"]


@dataclass(frozen=True)
class ResumeEvent:
    """One resumption of an interrupted run (an entry of the root attribute ``resumes``).

    Attributes
    ----------
    time : str
        When the run was resumed (ISO 8601, UTC).
    steps_on_disk : int
        Steps the file held then.
    next_plan_index : int
        The smallest plan index not on disk: the step the run resumed from.
    previous_status, previous_message : str
        How the interrupted run had ended (``exit_status`` and ``exit_message`` before).
    """

    time: str
    steps_on_disk: int
    next_plan_index: int
    previous_status: str
    previous_message: str


@dataclass(frozen=True, eq=False)
class RunData:
    """What every measurement file holds, whatever its kind.

    Attributes
    ----------
    path : Path
        The file read.
    format_version : int
        Version of the contract the file follows.
    channels : tuple of ChannelInfo
        Acquired channels in acquisition (table) order; ``C = len(channels)``.
    actuator : Actuator
    complete : bool
        True only if the run ended normally.
    exit_status : str
        ``"running"`` (still under way or killed), ``"success"``, ``"aborted"``, ``"failed"``.
    exit_message : str
    created : datetime
        Creation time, timezone-aware (UTC).
    software : dict of str to str
        Package -> version of the writing software.
    config, setup : dict
        The run configuration and the lab setup (parsed ``config_json``, ``setup_json``).
    output_at_zero : bool or None
        Whether the ramp of the output to 0 V at the end of the run completed (format_version
        2); None for a version-1 file, which does not say.
    resumes : tuple of ResumeEvent
        Each time the run was interrupted and resumed, oldest first (empty for a run never
        resumed, and for a version-1 file, which does not record them).
    """

    path: Path
    format_version: int
    channels: tuple[ChannelInfo, ...]
    actuator: Actuator
    complete: bool
    exit_status: str
    exit_message: str
    created: datetime
    software: dict[str, str]
    config: dict[str, Any]
    setup: dict[str, Any]
    output_at_zero: bool | None
    resumes: tuple[ResumeEvent, ...]

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Channel names in table order."""
        return tuple(ch.name for ch in self.channels)

    @property
    def drive_force_index(self) -> int:
        """Index of the drive-force channel in the table."""
        return next(i for i, ch in enumerate(self.channels) if ch.role == "drive-force")

    def channel_index(self, channel: str | int) -> int:
        """Index of a channel given by name (or an index, checked and returned as is)."""
        n = len(self.channels)
        if isinstance(channel, int | np.integer) and not isinstance(channel, bool):
            if not 0 <= channel < n:
                raise IndexError(f"{self.path}: channel index {channel} outside 0..{n - 1}")
            return int(channel)
        for i, ch in enumerate(self.channels):
            if ch.name == channel:
                return i
        raise KeyError(f"{self.path}: no channel named {channel!r}; channels: {self.channel_names}")

    def response_channels(self) -> tuple[ChannelInfo, ...]:
        """The channels of role ``"response"``, in table order."""
        return tuple(ch for ch in self.channels if ch.role == "response")


@dataclass(frozen=True, eq=False)
class SteppedSineData(RunData):
    """A stepped multi-sine run: plan and completed steps.

    ``n`` is the number of completed steps (in measured order), ``C`` channels, ``H`` orders,
    ``L`` levels.

    Attributes
    ----------
    levels_n : ndarray, shape (L,), N
        Target fundamental force amplitudes.
    orders_num, orders_den : ndarray of int64, shape (H,)
        Orders as fractions of the fundamental (see :attr:`orders`).
    force_targets : ndarray, shape (L, H), complex, N
        Target force phasors (phase of order k relative to k times the fundamental's phase).
    plan_index, level_index : ndarray of int64, shape (n,)
    sweep_direction : ndarray of int8, shape (n,)
        +1 up, -1 down.
    frequency_target_hz, frequency_hz : ndarray, shape (n,), Hz
        Planned and realised fundamental frequency.
    force : ndarray, shape (n, H), complex, N
        Drive-force phasors.
    force_std : ndarray, shape (n, H), N
        Standard errors of ``force`` (may be 0: divide through :func:`safe_std`).
    response : ndarray, shape (n, C, H), complex, channel units
        Phasors of every channel (the drive-force channel included).
    response_std : ndarray, shape (n, C, H), channel units
    drive : ndarray, shape (n, H), complex, V
        Output voltage phasors.
    n_blocks, control_iterations : ndarray of int64, shape (n,)
    control_converged : ndarray of bool, shape (n,)
    control_error : ndarray, shape (n,)
        Final max_k |F_k - F_target,k| / |F_target,1|.
    timestamp : ndarray, shape (n,), s
        POSIX time of completion.
    raw_plan_indices : tuple of int
        Completed steps with raw time data in ``/raw`` (read with :func:`read_raw`).
    extra_orders_num, extra_orders_den : ndarray of int64, shape (E,)
        Orders the drive does not contain at which the drive force was recorded too (see
        :attr:`extra_orders`); ``E = 0`` for a file without them.
    extra_force : ndarray, shape (n, E), complex, N
        Drive-force phasors at the extra orders: the shaker's push-back at harmonics the
        structure's response carries. A model driven by the measured force is driven by these
        too.
    extra_force_std : ndarray, shape (n, E), N
    """

    levels_n: np.ndarray
    orders_num: np.ndarray
    orders_den: np.ndarray
    force_targets: np.ndarray
    plan_index: np.ndarray
    level_index: np.ndarray
    sweep_direction: np.ndarray
    frequency_target_hz: np.ndarray
    frequency_hz: np.ndarray
    force: np.ndarray
    force_std: np.ndarray
    response: np.ndarray
    response_std: np.ndarray
    drive: np.ndarray
    n_blocks: np.ndarray
    control_iterations: np.ndarray
    control_converged: np.ndarray
    control_error: np.ndarray
    timestamp: np.ndarray
    raw_plan_indices: tuple[int, ...]
    extra_orders_num: np.ndarray = None  # type: ignore[assignment]
    extra_orders_den: np.ndarray = None  # type: ignore[assignment]
    extra_force: np.ndarray = None  # type: ignore[assignment]
    extra_force_std: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        empty = {
            "extra_orders_num": np.zeros(0, np.int64),
            "extra_orders_den": np.zeros(0, np.int64),
            "extra_force": np.zeros((self.n_steps, 0), complex),
            "extra_force_std": np.zeros((self.n_steps, 0)),
        }
        for name, value in empty.items():
            if getattr(self, name) is None:
                value.flags.writeable = False
                object.__setattr__(self, name, value)

    @property
    def extra_orders(self) -> tuple[Fraction, ...]:
        """The extra orders as exact fractions, shape (E,)."""
        return tuple(
            Fraction(int(a), int(b))
            for a, b in zip(self.extra_orders_num, self.extra_orders_den, strict=True)
        )

    @property
    def orders(self) -> tuple[Fraction, ...]:
        """Orders of the fundamental as exact fractions, shape (H,)."""
        return tuple(
            Fraction(int(a), int(b)) for a, b in zip(self.orders_num, self.orders_den, strict=True)
        )

    @property
    def n_steps(self) -> int:
        """Number of completed steps ``n``."""
        return int(self.plan_index.shape[0])

    def order_index(self, order: Fraction | int | str) -> int:
        """Index of an order given as a fraction, an int or a string like ``"1/2"``."""
        want = Fraction(order)
        try:
            return self.orders.index(want)
        except ValueError:
            raise KeyError(
                f"{self.path}: order {want} not measured; orders: {[str(o) for o in self.orders]}"
            ) from None

    def take(self, rows: Any) -> SteppedSineData:
        """The same run restricted to some steps.

        Parameters
        ----------
        rows : array_like of bool, shape (n,), or of int
            Mask or indices of the steps to keep (in the order given).
        """
        idx = np.arange(self.n_steps)[np.asarray(rows)]
        changes: dict[str, Any] = {}
        for spec in step_fields(self.extra_orders_num.size):
            arr = getattr(self, spec.field)[idx]
            arr.flags.writeable = False
            changes[spec.field] = arr
        kept = set(changes["plan_index"].tolist())
        changes["raw_plan_indices"] = tuple(p for p in self.raw_plan_indices if p in kept)
        return dataclasses.replace(self, **changes)

    def select(
        self,
        *,
        level_index: int | Iterable[int] | None = None,
        sweep_direction: int | None = None,
    ) -> SteppedSineData:
        """Steps of some levels and/or one sweep direction, in measured order.

        Parameters
        ----------
        level_index : int or iterable of int, optional
            Row(s) of :attr:`levels_n` to keep (all if None).
        sweep_direction : {+1, -1}, optional
            Keep only upward (+1) or downward (-1) steps (both if None).
        """
        mask = np.ones(self.n_steps, dtype=bool)
        if level_index is not None:
            wanted = [level_index] if isinstance(level_index, int | np.integer) else level_index
            wanted = [int(i) for i in wanted]
            bad = [i for i in wanted if not 0 <= i < self.levels_n.size]
            if bad:
                raise IndexError(
                    f"{self.path}: level_index {bad} outside 0..{self.levels_n.size - 1}"
                )
            mask &= np.isin(self.level_index, wanted)
        if sweep_direction is not None:
            if sweep_direction not in (1, -1):
                raise ValueError(f"sweep_direction must be +1 or -1, got {sweep_direction!r}")
            mask &= self.sweep_direction == sweep_direction
        return self.take(mask)

    def frf(self, channel: str | int) -> np.ndarray:
        """Multi-harmonic FRF of one channel: its phasor over the force phasor, per order.

        Parameters
        ----------
        channel : str or int
            Channel name or table index.

        Returns
        -------
        ndarray, shape (n, H), complex, channel unit per N
            ``response[:, c, k] / force[:, k]`` (receptance, mobility or accelerance depending
            on the channel's quantity); NaN where a force phasor is exactly 0.
        """
        c = self.channel_index(channel)
        zero = self.force == 0
        out = self.response[:, c, :] / np.where(zero, 1.0, self.force)
        out[zero] = np.nan
        return out


@dataclass(frozen=True, eq=False)
class RandomData(RunData):
    """A random-excitation run: H1 FRFs of every channel to the drive force.

    Attributes
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
    h1 : ndarray, shape (nf, C), complex, channel unit per N
        The drive-force column is 1.
    coherence : ndarray, shape (nf, C)
    force_psd : ndarray, shape (nf,), N^2/Hz
        One-sided.
    estimator : str
        ``"H1"``.
    n_averages : int
    window : str
    overlap : float
        Fraction 0-1.
    fs_hz : float
        Sampling rate [Hz].
    rms_force_n : float
        RMS drive force [N].
    """

    frequency_hz: np.ndarray
    h1: np.ndarray
    coherence: np.ndarray
    force_psd: np.ndarray
    estimator: str
    n_averages: int
    window: str
    overlap: float
    fs_hz: float
    rms_force_n: float

    def frf(self, channel: str | int) -> np.ndarray:
        """H1 of one channel, shape (nf,), complex, channel unit per N."""
        return self.h1[:, self.channel_index(channel)]


@dataclass(frozen=True, eq=False)
class RawRecord:
    """Raw time data of one step: ``/raw/<plan_index>``.

    Attributes
    ----------
    plan_index : int
    samples : ndarray of float32, shape (n_samples, C), channel units
    fs_hz : float
        Sampling rate [Hz].
    t0_s : float
        Time of the first sample after the drive started [s].
    """

    plan_index: int
    samples: np.ndarray
    fs_hz: float
    t0_s: float
