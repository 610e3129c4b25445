"""The nonlinear calibration metric of the paper (eq. 9-11).

``delta = eps^H W eps`` with ``eps`` the stacked real and imaginary parts of the differences
between analytical and measured multi-harmonic FRFs of the selected steps, channels and orders.
By default ``W`` comes from the file's phasor uncertainties (each real and imaginary part divided
by its standard error, ``sigma / sqrt(2)`` of the complex one, so ``delta`` is a chi-square);
``weighting="identity"`` is the paper's ``W = I``. A selected FRF with a standard error of
zero is refused under uncertainty weighting (:func:`~analysis.predict.check_standard_errors`
says why), never floored nor silently unweighted.
"""

from __future__ import annotations

import inspect
import logging

import numpy as np

from analysis.calibration.parameters import ParameterSpace
from analysis.measurement_file import require_steps
from analysis.predict import CostBound, SteppedSinePredictor, check_standard_errors

__all__ = ["FRFObjective"]

log = logging.getLogger(__name__)


class FRFObjective:
    """Residuals and Jacobian of the FRF metric in scaled parameter coordinates.

    Parameters
    ----------
    predictor : SteppedSinePredictor
    space : ParameterSpace
    mask : ndarray of bool, shape (n_steps, n_channels), optional
        Which (step, channel) FRFs enter (default: all); every order of a selected FRF enters.
    weighting : {"uncertainty", "identity"}
    """

    def __init__(
        self,
        predictor: SteppedSinePredictor,
        space: ParameterSpace,
        mask: np.ndarray | None = None,
        weighting: str = "uncertainty",
    ) -> None:
        if weighting not in ("uncertainty", "identity"):
            raise ValueError(f"weighting: expected 'uncertainty' or 'identity', got {weighting!r}")
        self.predictor, self.space = predictor, space
        data = getattr(predictor, "data", None)
        if data is not None and getattr(data, "n_steps", 1) == 0:
            require_steps(data)  # names the file and why its run ended
        H, std = predictor.measured()
        n, C, _ = H.shape
        m = np.ones((n, C), bool) if mask is None else np.asarray(mask, bool)
        if m.shape != (n, C):
            raise ValueError(f"mask: expected shape {(n, C)}, got {m.shape}")
        selected = int(m.any(axis=1).sum())
        m = m & np.all(np.isfinite(H), axis=2)
        if not m.any():
            where = f"{data.path}: " if data is not None and hasattr(data, "path") else ""
            raise ValueError(
                f"{where}the selection contains no measured FRF ({selected} of {n} steps "
                "selected, none with a finite FRF)"
            )
        self.mask = m
        self.rows = np.flatnonzero(m.any(axis=1))
        self.H = H
        if weighting == "uncertainty" and data is not None:
            # refused, not floored nor silently unweighted (see check_standard_errors)
            check_standard_errors(
                data,
                list(getattr(predictor, "channel_names", [])) or [str(c) for c in range(C)],
                np.where(m[:, :, None], H, np.nan),
                std,
                remedy="calibrate with --identity (W = I, the paper's metric) to fit without "
                "them, or give the file its standard errors",
            )
        if weighting == "identity":
            self.sigma = np.ones_like(std)
            self._weight = np.ones_like(std)
        else:
            positive = std[np.isfinite(std) & (std > 0)]
            self.sigma = np.maximum(np.nan_to_num(std, nan=positive.max()), positive.min())
            # sigma is the complex standard error; each of the real and imaginary parts has
            # sigma / sqrt(2) (measurement-file contract), so r is a unit-variance residual
            self._weight = np.sqrt(2) / self.sigma
        self.weighting = weighting
        self.n_evaluations = 0
        try:
            accepts = "stop_at_failure" in inspect.signature(predictor.predict).parameters
        except (TypeError, ValueError):  # pragma: no cover - a predict without a signature
            accepts = False
        #: :meth:`cost` stops a prediction at its first selected step without a solution
        #: (where the predictor can: ``predict(..., stop_at_failure=True)``).
        self.stop_at_failure = accepts
        #: :meth:`cost` can stop a prediction once its metric exceeds a limit (where the
        #: predictor takes a :class:`~analysis.predict.CostBound`).
        self.can_bound = accepts and "bound" in inspect.signature(predictor.predict).parameters

    @property
    def n_residuals(self) -> int:
        return 2 * int(self.mask.sum()) * self.H.shape[2]

    def _stack(self, z: np.ndarray) -> np.ndarray:
        e = (z * self._weight)[self.mask].ravel()
        return np.concatenate([e.real, e.imag])

    def __call__(self, theta: np.ndarray, want_jac: bool = True):
        """Residuals (m,) and Jacobian (m, n) at scaled coordinates ``theta``.

        Residuals are NaN where a step of the selection did not converge (an infeasible point
        for the optimiser), and for parameter values the elements refuse (e.g. a negative gap).
        """
        return self._evaluate(theta, want_jac, stop_at_failure=False)

    def step_cost(self, row: int, frf: np.ndarray) -> float:
        """Step ``row``'s term of the cost (its FRFs ``frf``, shape (channels, orders)): the
        cost is the sum of these non-negative terms over the selected steps."""
        e = ((frf - self.H[row]) * self._weight[row])[self.mask[row]]
        return 0.5 * float(np.sum(e.real**2 + e.imag**2))

    def _evaluate(self, theta: np.ndarray, want_jac: bool, stop_at_failure: bool, bound=None):
        self.n_evaluations += 1
        sp = self.space
        p = sp.to_physical(theta)
        kw: dict = {"stop_at_failure": True} if stop_at_failure else {}
        if bound is not None:
            kw["bound"] = bound
        try:
            pred = self.predictor.predict(
                sp.as_dict(p), sp.names if want_jac else (), rows=self.rows, **kw
            )
        except ValueError as exc:
            log.debug("infeasible parameters %s: %s", p, exc)
            return np.full(self.n_residuals, np.nan), None
        if (
            getattr(pred, "floor", None) is not None
        ):  # stopped above the bound's limit: no residuals
            return np.full(self.n_residuals, np.nan), None
        if not pred.converged[self.rows].all():
            return np.full(self.n_residuals, np.nan), None
        r = self._stack(pred.frf - self.H)
        if not want_jac:
            return r, None
        scale = sp.dp_dtheta(theta)
        J = np.column_stack(
            [self._stack(pred.d_frf[name]) * scale[i] for i, name in enumerate(sp.names)]
        )
        return r, J

    def cost_of(self, pred) -> float:
        """``delta / 2`` of a prediction made at this objective's steps (``inf`` where a step
        did not converge): the metric of a model already predicted, without solving again."""
        if not pred.converged[self.rows].all():
            return np.inf
        r = self._stack(pred.frf - self.H)
        return 0.5 * float(r @ r)

    def cost(self, theta: np.ndarray, stop_at_failure: bool | None = None) -> float:
        """``delta / 2`` at ``theta`` (``inf`` where infeasible).

        The cost is ``inf`` as soon as one selected step has no solution, so the prediction
        stops there (``stop_at_failure``, default :attr:`stop_at_failure`: where the predictor
        can): a start far from the data costs a part of a prediction, and every cost is the
        same, bit for bit, as without it.
        """
        return self.bounded_cost(theta, None, stop_at_failure)[0]

    def bounded_cost(
        self, theta: np.ndarray, limit: float | None, stop_at_failure: bool | None = None
    ) -> tuple[float, bool]:
        """``(cost, exact)`` at ``theta``: :meth:`cost`, except that a prediction whose cost
        provably exceeds ``limit`` (the sum of its final step terms, :meth:`step_cost`, already
        does) is stopped there and that lower bound, above ``limit``, is returned with
        ``exact`` False. ``limit`` None (or a predictor that cannot stop): always exact."""
        stop = self.stop_at_failure if stop_at_failure is None else stop_at_failure
        bound = None
        if limit is not None and np.isfinite(limit) and self.can_bound:
            bound = CostBound(self.step_cost, float(limit))
        r, _ = self._evaluate(theta, False, stop, bound)
        if bound is not None and bound.exceeded:
            return bound.floor, False
        return (0.5 * float(r @ r) if np.all(np.isfinite(r)) else np.inf), True
