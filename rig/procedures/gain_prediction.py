"""Starting gain of each stepped-sine step, predicted from the steps already measured.

Near a resonance the drive-to-force gain of a shaker on a structure changes fast with
frequency (the force drops where the structure's driving-point mobility peaks) and, with a
nonlinear element, with level. A step that starts from the previous step's gain then misses its
target by tens of percent on the first drive, needs more iterations, and can overshoot. The
predictor uses what the run has learnt:

1. the same frequency at a lower level (the previous sweep over these frequencies) scaled by
   how the gain at the previous frequency changed between that level and this one:
   ``G(f, L) = G(f, L') * G(f_prev, L) / G(f_prev, L')``, unless it differs from rule 2 by
   more than ``BRANCH_JUMP_RATIO`` (the lower level's response jumped between the two
   frequencies, off the fold of its resonance, while this sweep is still on its branch);
2. otherwise an extrapolation along the sweep from the last two steps, in the logarithm of the
   complex gain (magnitude and phase), ``log G(f) = log G1 + r (log G1 - log G0)`` with
   ``r = (f - f1) / (f1 - f0)`` limited to [0, 1];
3. otherwise the previous step's gain, or the loop check's.

Gains are per order (the diagonal of the controller's matrix): the fundamental's from the
recorded force over the recorded drive (the secant through zero, which is what the first drive
``V = T / G`` needs), the other orders' from the controller's final estimate when there is one.
A resumed run rebuilds the history from the steps on disk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rig.config.plans import PlannedStep

__all__ = ["GainHistory"]

_FREQ_KEY_DECIMALS = 6
# rule 1 is dropped for the sweep's own extrapolation when the two differ by more than this factor
BRANCH_JUMP_RATIO = 2.0


@dataclass(frozen=True)
class _Entry:
    plan_index: int
    level_index: int
    sweep_direction: int
    frequency_hz: float  # planned
    realised_hz: float
    gain: np.ndarray  # (H,) complex, N/V
    matrix: np.ndarray | None  # (H, H) complex: the controller's final estimate
    drive: np.ndarray  # (H,) complex, V: the recorded drive


class GainHistory:
    """Gains of the steps measured so far, and predictions for the next ones.

    Parameters
    ----------
    fundamental_index : int
        Column of order 1.
    orders : sequence of float, optional
        The orders (to turn the other orders' drives with the fundamental's phase).
    """

    def __init__(self, fundamental_index: int, orders=None) -> None:
        self.i1 = fundamental_index
        self.orders = None if orders is None else [float(o) for o in orders]
        self._by_index: dict[int, _Entry] = {}
        self._by_key: dict[tuple[int, int, float], _Entry] = {}

    def __len__(self) -> int:
        return len(self._by_index)

    def add(
        self,
        step: PlannedStep,
        drive_v: np.ndarray,
        force_n: np.ndarray,
        matrix: np.ndarray | None = None,
        frequency_hz: float | None = None,
    ) -> None:
        """Record a measured step.

        Parameters
        ----------
        step : PlannedStep
        drive_v, force_n : ndarray, shape (H,), complex
            Recorded drive and force phasors.
        matrix : ndarray, shape (H, H), complex, optional
            The controller's final gain estimate.
        frequency_hz : float, optional
            Realised fundamental [Hz] (default the planned one); extrapolation along a sweep
            uses realised frequencies, which the DAQ clock spaces unevenly.
        """
        drive = np.asarray(drive_v, dtype=complex)
        force = np.asarray(force_n, dtype=complex)
        with np.errstate(divide="ignore", invalid="ignore"):
            secant = np.where(np.abs(drive) > 0, force / drive, np.nan)
        gain = secant.copy()
        if matrix is not None:
            diag = np.diag(matrix).copy()
            others = np.arange(gain.size) != self.i1
            gain[others] = diag[others]
        if not np.all(np.isfinite(gain)) or np.any(gain == 0):
            if matrix is None:
                return
            gain = np.diag(matrix).copy()
        entry = _Entry(
            step.plan_index,
            step.level_index,
            step.sweep_direction,
            step.frequency_hz,
            float(frequency_hz) if frequency_hz is not None else step.frequency_hz,
            gain,
            None if matrix is None else np.array(matrix, dtype=complex),
            drive,
        )
        self._by_index[step.plan_index] = entry
        self._by_key[self._key(step.level_index, step.sweep_direction, step.frequency_hz)] = entry

    @staticmethod
    def _key(level: int, direction: int, f: float) -> tuple[int, int, float]:
        return (level, direction, round(f, _FREQ_KEY_DECIMALS))

    def _lower_level(self, level: int, direction: int, f: float) -> _Entry | None:
        for lower in range(level - 1, -1, -1):
            e = self._by_key.get(self._key(lower, direction, f))
            if e is not None:
                return e
        return None

    def predict(
        self, step: PlannedStep, previous: PlannedStep | None, frequency_hz: float | None = None
    ) -> np.ndarray | None:
        """Predicted gain matrix for ``step`` (None if nothing is known yet).

        Parameters
        ----------
        step : PlannedStep
        previous : PlannedStep, optional
            The step before it in the plan (its sweep neighbour unless ``step`` starts a sweep).
        frequency_hz : float, optional
            The fundamental the step will realise [Hz] (default the planned one).

        Returns
        -------
        ndarray, shape (H, H), complex, N/V, or None
            The fundamental's gain predicted as in the module notes; the other orders' gains
            and the couplings between orders from the nearest estimate (the previous step of
            the sweep, else the same frequency at a lower level, else the latest step).
        """
        if not self._by_index:
            return None
        last = self._by_index[max(self._by_index)]
        prev = None
        if previous is not None and not step.first_of_sweep:
            prev = self._by_index.get(previous.plan_index)
        same_f = self._lower_level(step.level_index, step.sweep_direction, step.frequency_hz)
        nearest = prev or same_f or last
        f = step.frequency_hz if frequency_hz is None else float(frequency_hz)
        gain = self._fundamental(step, prev, same_f, f)
        if gain is None:
            gain = nearest.gain[self.i1]
        if nearest.matrix is not None:
            matrix = nearest.matrix.copy()
        else:
            matrix = np.diag(nearest.gain)
        matrix[self.i1, self.i1] = gain
        return matrix

    def predict_drive(
        self,
        step: PlannedStep,
        previous: PlannedStep | None,
        targets: np.ndarray,
        frequency_hz: float | None = None,
    ) -> np.ndarray | None:
        """First drive of ``step`` (None if nothing is known yet).

        The fundamental's drive is its target over the predicted gain. The other orders mostly
        cancel force the structure's nonlinearity generates from the fundamental, so their
        drive is taken from the nearest measured step (as in :meth:`predict`), scaled with the
        fundamental's drive amplitude and turned with ``k`` times its phase change.

        Parameters
        ----------
        step, previous : PlannedStep
        targets : ndarray, shape (H,), complex, N
        frequency_hz : float, optional
            The fundamental the step will realise [Hz].

        Returns
        -------
        ndarray, shape (H,), complex, V, or None
        """
        matrix = self.predict(step, previous, frequency_hz)
        if matrix is None:
            return None
        i1 = self.i1
        prev = None
        if previous is not None and not step.first_of_sweep:
            prev = self._by_index.get(previous.plan_index)
        same_f = self._lower_level(step.level_index, step.sweep_direction, step.frequency_hz)
        source = prev or same_f or self._by_index[max(self._by_index)]
        v1 = targets[i1] / matrix[i1, i1]
        before = self._sweep_neighbour(prev)
        if before is not None:
            f = step.frequency_hz if frequency_hz is None else float(frequency_hz)
            r = (f - prev.realised_hz) / (prev.realised_hz - before.realised_hz)
            drive = prev.drive + min(max(r, 0.0), 1.0) * (prev.drive - before.drive)
            drive[i1] = v1
            return drive
        ref = source.drive[i1]
        drive = source.drive.copy()
        if abs(ref) > 0:
            turn = np.angle(v1 / ref)
            orders = self.orders if self.orders is not None else np.arange(1, drive.size + 1)
            drive = drive * abs(v1 / ref) * np.exp(1j * np.asarray(orders, float) * turn)
        drive[i1] = v1
        return drive

    def _fundamental(self, step: PlannedStep, prev: _Entry | None, same_f: _Entry | None, f: float):
        i1 = self.i1
        along = None if prev is None else self._along_sweep(prev, f)
        if same_f is not None and prev is not None:
            ref = self._lower_level(step.level_index, step.sweep_direction, prev.frequency_hz)
            if ref is not None and ref.level_index == same_f.level_index:
                scaled = same_f.gain[i1] * prev.gain[i1] / ref.gain[i1]
                # the lower level's gain changed between the two frequencies by more than this
                # sweep's own trend allows: its response jumped to another branch there (the
                # fold of its resonance), which says nothing about this sweep's branch
                if abs(np.log(abs(scaled / along))) <= np.log(BRANCH_JUMP_RATIO):
                    return scaled
                return along
        if same_f is not None:
            return same_f.gain[i1]
        return along

    def _along_sweep(self, prev: _Entry, f: float) -> np.ndarray:
        """The fundamental's gain extrapolated along the sweep (rule 2, else rule 3)."""
        before = self._sweep_neighbour(prev)
        if before is not None:
            r = (f - prev.realised_hz) / (prev.realised_hz - before.realised_hz)
            return _log_extrapolate(before.gain[self.i1], prev.gain[self.i1], min(max(r, 0.0), 1.0))
        return prev.gain[self.i1]

    def _sweep_neighbour(self, entry: _Entry | None) -> _Entry | None:
        """The step measured just before ``entry`` in the same sweep, if any."""
        if entry is None:
            return None
        before = self._by_index.get(entry.plan_index - 1)
        if (
            before is not None
            and before.level_index == entry.level_index
            and before.sweep_direction == entry.sweep_direction
            and before.realised_hz != entry.realised_hz
        ):
            return before
        return None


def _log_extrapolate(g0: np.ndarray, g1: np.ndarray, r: float) -> np.ndarray:
    """``exp(log g1 + r (log g1 - log g0))`` with the phase change taken in (-pi, pi]."""
    ratio = g1 / g0
    return g1 * np.exp(r * (np.log(np.abs(ratio)) + 1j * np.angle(ratio)))
