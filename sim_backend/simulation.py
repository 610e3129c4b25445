"""The simulated rig's timeline: what the sensors see, sample by sample, as the drive changes.

The timeline is a sequence of *segments*, each started by a change of the drive (a new DAQ
waveform with its cross-fade, or a change of the amplifier's state: muted, tripped, gain). A
segment has a *target*: the waveform it fades to, times the amplifier gain. Two engines
produce the samples:

``"mhb"`` segments (periodic targets with at most ``MAX_DRIVE_ORDER`` harmonics of a base)
    The response is the target's periodic steady state from the multi-harmonic balance of the
    coupled nonlinear rig plus a transient ``eta_tr`` in the modal coordinates of the coupled
    *linear* rig (structure, shaker, amplifier; :mod:`sim_backend.statespace`). At the segment
    start the transient takes up the difference between the state the rig is in and the new
    steady state; during the fade it is driven by the drive's deviation from the target
    (exact for the sampled drive), and afterwards it decays freely with the coupled system's
    own poles. A lightly damped mode near the drive therefore rings for many periods after a
    level or frequency change, with its beating against the drive, as on the rig. What is
    approximate: nonlinear forces act on the steady state, not on the transient (a contact
    does not shorten the ring-down); ``mode="time"`` integrates everything.
``"time"`` segments (other drives, e.g. random; every segment in ``mode="time"``; a periodic
    target whose balance failed)
    The full nonlinear rig is integrated sample by sample (:mod:`sim_backend.integrator`).

Both engines share the modal state, so the timeline hands the exact rig state from one
segment to the next whatever their engines. The amplifier's protection is checked against the
coil current: at the segment start from the target's steady-state peak current (the trip is
placed where the cross-fade reaches the limit), and sample by sample in time segments. A trip
latches the :class:`~sim_backend.amplifier.AmplifierModel`, which mutes the drive from then on.
IEPE sensors are AC coupled: the mean of a steady state is not seen.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from analysis.executors import one_blas_thread
from sim_backend.amplifier import AmplifierModel
from sim_backend.drive import DriveProgram, analyse_period
from sim_backend.integrator import TimeStepper
from sim_backend.rig_model import MAX_DRIVE_ORDER, RigModel, SteadyState

__all__ = ["MODES", "RigSimulation"]

logger = logging.getLogger(__name__)

MODES = ("mhb", "time")


@dataclass
class _Segment:
    start: int
    program: DriveProgram
    gain: float
    engine: str
    steady: SteadyState | None = None
    sensor_phasors: np.ndarray | None = None  # (H, n_s) for harmonics 1..H
    fade_eta: np.ndarray | None = None  # (n_f + 1, p) transient at start..fade_end
    fade_end: int = 0
    eta: np.ndarray | None = None  # time engine: full state at `index`
    forces: np.ndarray | None = None
    index: int = 0


class RigSimulation:
    """Sensor signals of the simulated rig for a drive program that changes over time.

    Parameters
    ----------
    rig : RigModel
        Physics for the configured sensors (``rig.sensors``; voltage sensors are skipped).
    amplifier : AmplifierModel
        Its gain and state are read at every drive change and every :meth:`take`.
    sample_rate_hz : float
    mode : {"mhb", "time"}
        Engine for periodic drives (see the module notes).
    substeps : int
        Integration steps per sample in time segments.
    """

    def __init__(
        self,
        rig: RigModel,
        amplifier: AmplifierModel,
        sample_rate_hz: float,
        mode: str = "mhb",
        substeps: int = 1,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"mode: expected one of {MODES}, got {mode!r}")
        self.rig = rig
        self.amp = amplifier
        self.fs = float(sample_rate_hz)
        self.mode = mode
        sp = rig.space
        self.sensors = [s for s in rig.sensors if s.quantity != "voltage"]
        rows = [rig.sensor_rows(s) for s in self.sensors]
        L = rig.problem.L
        if rows:
            self._C = sp.modal(np.array([r for r, _ in rows]))
            self._D = np.array([f for _, f in rows]) @ L.T
        else:
            self._C = np.zeros((0, sp.size), dtype=complex)
            self._D = np.zeros((0, L.shape[0]))
        self._c_current = sp.modal(sp.current_row()[None, :])[0]
        self._columns = [rig.sensor_output(s) for s in self.sensors]
        self._current_column = rig.output_dofs.index(rig.coupled.current)
        self.stepper = TimeStepper(sp, rig.problem, self.fs, substeps)
        self._step = sp.discretise(1.0 / self.fs)
        self.reset()

    # -- public -------------------------------------------------------------------------------
    def reset(self) -> None:
        """Rig at rest, 0 V, sample index 0."""
        p = self.rig.space.size
        self.index = 0
        self.taken = 0
        self._buffer: list[np.ndarray] = []
        self._peak_current = 0.0
        self._trip: tuple[int, float] | None = None
        self._last_steady: SteadyState | None = None
        self._segment = self._new_segment(
            0, DriveProgram.zero(), np.zeros(p, complex), self._gain()
        )

    def set_program(self, program: DriveProgram, start: int) -> None:
        """The drive follows ``program`` from sample ``start`` (>= the generated samples)."""
        if start < self.index:
            raise ValueError(f"a drive change at {start} lies before sample {self.index}")
        with one_blas_thread():  # see take
            self._buffer.append(self._generate(start))
            self._transition(start, program)

    def take(self, n: int) -> np.ndarray:
        """The next ``n`` samples of every sensor, shape (n, n_sensors), N and m/s^2."""
        stop = self.taken + n
        if stop > self.index:
            # the rig's matrices are small: one BLAS thread is faster alone and keeps two
            # simulated tests on one machine from stalling each other
            with one_blas_thread():
                self._buffer.append(self._generate(stop))
        data = np.concatenate(self._buffer) if len(self._buffer) != 1 else self._buffer[0]
        out, rest = data[:n], data[n:]
        self._buffer = [rest] if rest.shape[0] else []
        self.taken = stop
        return out

    @property
    def engine(self) -> str:
        """Engine of the segment in force: ``"mhb"`` or ``"time"``."""
        return self._segment.engine

    @property
    def steady(self) -> SteadyState | None:
        """Steady state of the segment in force (mhb segments), for reference solutions."""
        return self._segment.steady

    # -- timeline -------------------------------------------------------------------------------
    def _gain(self) -> float:
        state = self.amp.state()
        return state.gain_v_per_v if state.live else 0.0

    def _generate(self, stop: int) -> np.ndarray:
        """Samples from :attr:`index` to ``stop`` (exclusive), advancing the timeline."""
        parts = [np.zeros((0, len(self.sensors)))]
        while self.index < stop:
            if self._trip is not None and self._trip[0] <= self.index:
                self.amp.check_current(self._trip[1])
                self._trip = None
            gain = self._gain()
            if gain != self._segment.gain:
                self._transition(self.index, self._segment.program)
            end = stop
            if self._trip is not None:
                end = min(end, max(self._trip[0], self.index + 1))
            chunk = self._samples(self._segment, self.index, end)
            parts.append(chunk)
            self.index += chunk.shape[0]
        return np.concatenate(parts)

    def _transition(self, k: int, program: DriveProgram) -> None:
        eta = self._full_state(self._segment, k)
        self._trip = None
        self._segment = self._new_segment(k, program, eta, self._gain())

    def _new_segment(self, k: int, program: DriveProgram, eta: np.ndarray, gain: float) -> _Segment:
        content = analyse_period(program.wave)
        periodic = len(content.phasors) <= MAX_DRIVE_ORDER
        if self.mode == "mhb" and periodic:
            seg = self._mhb_segment(k, program, eta, gain, content)
            if seg is not None:
                return seg
        seg = _Segment(k, program, gain, "time", eta=eta, index=k)
        seg.forces = self.stepper.forces_at(eta)
        logger.debug("time segment from sample %d", k)
        return seg

    def _mhb_segment(self, k, program, eta, gain, content) -> _Segment | None:
        rig, sp = self.rig, self.rig.space
        n = program.period
        K = len(content.phasors)
        base = max(content.base_bin, 1)
        omega_base = 2 * np.pi * self.fs * base / n
        harmonics = np.arange(1, K + 1)
        hold = np.sinc(harmonics * base / n) ** 2
        steady = rig.steady_state(omega_base, gain * hold * content.phasors, self._last_steady)
        if not steady.converged:
            return None
        if np.any(steady.u):
            self._last_steady = steady
        w = steady.omegas
        phasors = np.zeros((w.size - 1, len(self.sensors)), dtype=complex)
        for i, (s, (col, sign)) in enumerate(zip(self.sensors, self._columns, strict=True)):
            factor = 1.0 if s.quantity == "force" else -(w[1:] ** 2)
            phasors[:, i] = sign * factor * steady.outputs[1:, col]
        t0 = (k - program.anchor) / self.fs
        eta_ss = sp.state_at(w, steady.u, steady.f_nl, np.array([t0]))[0]
        seg = _Segment(k, program, gain, "mhb", steady, phasors)
        fade_end = max(program.steady_from, k)
        seg.fade_end = fade_end
        tr = np.empty((fade_end - k + 1, sp.size), dtype=complex)
        tr[0] = eta - eta_ss
        if fade_end > k:
            j = np.arange(k, fade_end + 1)
            du = gain * (program.samples(j) - program.steady_samples(j))
            E, gA, gB = self._step.E, self._step.gA, self._step.gB
            for i in range(fade_end - k):
                tr[i + 1] = E * tr[i] + gA * du[i] + gB * du[i + 1]
        seg.fade_eta = tr
        self._check_current(seg, k, fade_end)
        logger.debug(
            "mhb segment from sample %d: %.5g Hz base, %d harmonic(s), fade %d samples",
            k,
            omega_base / (2 * np.pi),
            K,
            fade_end - k,
        )
        return seg

    def _check_current(self, seg: _Segment, k: int, fade_end: int) -> None:
        current = seg.steady.outputs[:, self._current_column]
        tau = 2 * np.pi * np.arange(256) / 256
        wave = (np.exp(1j * np.outer(tau, np.arange(current.size))) @ current).real
        peak = float(np.abs(wave).max())
        limit = self.amp.constants.current_limit_a
        previous, self._peak_current = self._peak_current, peak
        if peak <= limit:
            self.amp.check_current(peak)
            return
        j = np.arange(k, fade_end + 1)
        if fade_end > k:
            x = np.clip((j - seg.program.fade_start + 1) / max(seg.program.fade_len, 1), 0, 1)
            weight = 0.5 - 0.5 * np.cos(np.pi * x)
        else:
            weight = np.ones(1)
        reach = np.flatnonzero(weight * peak + (1 - weight) * previous > limit)
        self._trip = (int(j[reach[0]]) if reach.size else fade_end, peak)

    def _full_state(self, seg: _Segment, k: int) -> np.ndarray:
        if seg.engine == "time":
            if seg.index != k:
                raise RuntimeError(f"time segment is at sample {seg.index}, not {k}")
            return seg.eta
        return self._steady_eta(seg, np.array([k]))[0] + self._transient(seg, np.array([k]))[0]

    def _steady_eta(self, seg: _Segment, j: np.ndarray) -> np.ndarray:
        st = seg.steady
        t = (j - seg.program.anchor) / self.fs
        return self.rig.space.state_at(st.omegas, st.u, st.f_nl, t)

    def _transient(self, seg: _Segment, j: np.ndarray) -> np.ndarray:
        out = np.empty((j.size, self.rig.space.size), dtype=complex)
        early = j < seg.fade_end
        out[early] = seg.fade_eta[j[early] - seg.start]
        late = ~early
        if late.any():
            dt = (j[late] - seg.fade_end) / self.fs
            out[late] = np.exp(np.outer(dt, self.rig.space.lam)) * seg.fade_eta[-1]
        return out

    # -- samples ---------------------------------------------------------------------------------
    def _samples(self, seg: _Segment, a: int, b: int) -> np.ndarray:
        if seg.engine == "mhb":
            j = np.arange(a, b)
            t = (j - seg.program.anchor) / self.fs
            w = seg.steady.omegas[1:]
            y = (np.exp(1j * np.outer(t, w)) @ seg.sensor_phasors).real
            return y + (self._transient(seg, j) @ self._C.T).real
        return self._integrate(seg, a, b)

    def _integrate(self, seg: _Segment, a: int, b: int) -> np.ndarray:
        u = seg.gain * seg.program.samples(np.arange(a, b + 1))
        res = self.stepper.run(seg.eta, seg.forces, u)
        eta = np.vstack([seg.eta[None, :], res.eta])
        forces = np.vstack([seg.forces[None, :], res.forces])
        current = (eta @ self._c_current).real
        limit = self.amp.constants.current_limit_a
        over = np.flatnonzero(np.abs(current[:-1]) > limit)
        n = b - a
        if over.size:
            n = max(int(over[0]), 1)
            self._trip = (a + n, float(np.abs(current[: n + 1]).max()))
        else:
            self.amp.check_current(float(np.abs(current).max()))
        seg.eta, seg.forces, seg.index = eta[n], forces[n], a + n
        return (eta[:n] @ self._C.T).real + forces[:n] @ self._D.T
