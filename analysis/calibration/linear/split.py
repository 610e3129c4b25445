"""Which measured FRFs calibrate and which validate.

As in the paper, 9 of the 13 FRFs calibrate and 4 validate. :data:`DEFAULT_CALIBRATION_POINTS`
calibrates with points 1-8 and 11: the whole cantilever (it carries the drive, the contact and
most of the response), the top of the left post next to the clamp and the middle of the bottom
member. Points 9, 10, 12 and 13 validate: next to the connection corners and on the right post,
the frame regions the calibration set sees least, so the validation tests prediction where the
corner and mount parameters act. ``"information"`` instead picks the points that maximise
``det(J^T J)`` of the metric at the start (greedy D-optimal selection).
"""

from __future__ import annotations

import numpy as np

from analysis.calibration.linear.objective import EqualizedFRFObjective
from analysis.calibration.linear.run_frfs import CalibrationError, RunFRFs

__all__ = ["DEFAULT_CALIBRATION_POINTS", "most_informative_points", "split_channels"]

DEFAULT_CALIBRATION_POINTS = (1, 2, 3, 4, 5, 6, 7, 8, 11)


def split_channels(
    run: RunFRFs,
    chosen: tuple[int, ...] | str,
    obj: EqualizedFRFObjective,
    x0: np.ndarray,
    n_calibration: int | None = None,
) -> tuple[list[int], list[int]]:
    """Channel indices ``(calibration, validation)`` of ``run``.

    Parameters
    ----------
    run : RunFRFs
    chosen : tuple of int, "default" or "information"
        Calibration points. ``"default"`` is :data:`DEFAULT_CALIBRATION_POINTS` when all of them
        and at least one other point are measured, else ``"information"``.
    obj : EqualizedFRFObjective
        Over all channels of ``run`` (for ``"information"``).
    x0 : ndarray, shape (n,)
        Start point of the calibration (scaled).
    n_calibration : int, optional
        Points chosen by ``"information"`` (default ``round(9/13 * n_points)``).
    """
    points = sorted(set(run.points))
    if chosen == "default":
        fixed = set(DEFAULT_CALIBRATION_POINTS)
        chosen = DEFAULT_CALIBRATION_POINTS if fixed < set(points) else "information"
    if chosen == "information":
        n_cal = n_calibration or max(1, round(9 / 13 * len(points)))
        chosen = most_informative_points(run, obj, x0, min(n_cal, len(points)))
    missing = sorted(set(chosen) - set(points))
    if missing:
        raise CalibrationError(
            f"{run.source}: calibration point(s) {missing} not measured; measured: {points}"
        )
    cal = [i for i, p in enumerate(run.points) if p in chosen]
    val = [i for i, p in enumerate(run.points) if p not in chosen]
    return cal, val


def most_informative_points(
    run: RunFRFs, obj: EqualizedFRFObjective, x0: np.ndarray, n: int
) -> tuple[int, ...]:
    """Greedy D-optimal choice of ``n`` points: each adds most to ``log det(J^T J)``."""
    _, J = obj(x0, True)
    J = J[: obj.target.size].reshape(obj.target.shape + (-1,))  # (nk, C, n_par)
    points = sorted(set(run.points))
    fisher = {
        p: sum(J[:, i].T @ J[:, i] for i, q in enumerate(run.points) if q == p) for p in points
    }
    eps = 1e-9 * max(np.trace(F) for F in fisher.values()) * np.eye(J.shape[-1])
    chosen: list[int] = []
    F = np.zeros_like(eps)
    for _ in range(n):
        best = max(
            (p for p in points if p not in chosen),
            key=lambda p: np.linalg.slogdet(F + fisher[p] + eps)[1],
        )
        chosen.append(best)
        F = F + fisher[best]
    return tuple(sorted(chosen))
