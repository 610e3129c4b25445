"""The outcome of a pretest plan: ranking, the paper's Table 4, the chosen design's FIM,
its inverse and correlation indices; JSON and a text report."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from analysis.planning.candidates import Candidates, Configuration, NoiseModel
from analysis.planning.ranking import Ranking, configuration_at, configuration_index

__all__ = ["Correlations", "PlanResult", "RankedConfiguration"]


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _matrix(a: np.ndarray) -> list[list[float | None]]:
    return [[_finite(v) for v in row] for row in np.asarray(a, dtype=float)]


@dataclass(frozen=True)
class RankedConfiguration:
    """A configuration with its place in the ranking.

    Attributes
    ----------
    rank : int or None
        1 for the largest determinant; None for a configuration outside the candidates.
    configuration : Configuration
    log10_det : float
        ``log10 det FIM`` in the parameters' physical units (``-inf``: singular).
    log10_det_scaled : float
        The same in scaled parameters ``theta = P / s`` (what is ranked).
    """

    rank: int | None
    configuration: Configuration
    log10_det: float
    log10_det_scaled: float

    @property
    def det(self) -> float:
        """``det FIM`` in physical units (``inf`` beyond the float range)."""
        if self.log10_det > 308:
            return math.inf
        return 10.0**self.log10_det

    def to_dict(self) -> dict:
        """JSON-friendly fields (the columns of the paper's Table 4)."""
        c = self.configuration
        return {
            "rank": self.rank,
            "actuator": c.actuator,
            "levels_n": list(c.levels_n),
            "range_hz": c.frequency_range.label,
            "sensors": list(c.sensors),
            "det": _finite(self.det),
            "log10_det": _finite(self.log10_det),
        }


@dataclass(frozen=True)
class Correlations:
    """FIM, its inverse and the correlation indices of one configuration and step plan.

    Attributes
    ----------
    step_plan : str
        The frequency range's label (with any refinement).
    n_steps : int
        Frequency steps per level.
    fim : ndarray, shape (p, p)
        Fisher information in physical units (``1 / (unit_i unit_j)``).
    fim_inverse : ndarray, shape (p, p)
        Its inverse: the Cramer-Rao bound of the parameter covariance (``unit_i unit_j``),
        ``nan`` when singular.
    mac : ndarray, shape (p, p)
        MAC between the columns of the noise-whitened Jacobian (consistent with the FIM).
    mac_frf : ndarray, shape (p, p)
        MAC between the columns of the plain FRF Jacobian (the paper's identical sigma).
    """

    step_plan: str
    n_steps: int
    fim: np.ndarray
    fim_inverse: np.ndarray
    mac: np.ndarray
    mac_frf: np.ndarray

    def __post_init__(self) -> None:
        for name in ("fim", "fim_inverse", "mac", "mac_frf"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))

    def pair(self, a: int, b: int, frf: bool = False) -> float:
        """Correlation index of parameters ``a`` and ``b`` (indices)."""
        return float((self.mac_frf if frf else self.mac)[a, b])

    def to_dict(self) -> dict:
        return {
            "step_plan": self.step_plan,
            "n_steps": self.n_steps,
            "fim": _matrix(self.fim),
            "fim_inverse": _matrix(self.fim_inverse),
            "std": [_finite(math.sqrt(v)) if v >= 0 else None for v in np.diag(self.fim_inverse)],
            "mac": _matrix(self.mac),
            "mac_frf": _matrix(self.mac_frf),
        }


@dataclass(frozen=True)
class PlanResult:
    """Result of :func:`analysis.planning.plan_tests`.

    Attributes
    ----------
    parameters, units : tuple of str
        Planned parameters and their units.
    scales : ndarray, shape (p,)
        ``s`` of the scaled parameters ``theta = P / s`` used for ranking.
    candidates : Candidates
    noise : NoiseModel
    ranking : Ranking
        Every configuration's ``log10 det`` (scaled) and the order, best first.
    top : tuple of RankedConfiguration
        The best ones (the paper's Table 4).
    chosen : RankedConfiguration
        The configuration studied below (the best unless one was given).
    correlations : Correlations
        FIM, inverse and correlation indices of the chosen configuration.
    refined : Correlations or None
        The same with the frequency steps refined around the resonance.
    best_by_range : dict of str to float
        Best ``log10 det`` (physical) per frequency range (``-inf``: none identifiable).
    n_sweeps, n_steps : int
        Sweeps and frequency steps solved (with sensitivities).
    failed_steps : int
        Steps that did not converge (no information taken from them).
    timings : dict of str to float
        Wall times [s]: ``sweeps``, ``ranking``, ``study``, ``total``.
    """

    parameters: tuple[str, ...]
    units: tuple[str, ...]
    scales: np.ndarray
    candidates: Candidates
    noise: NoiseModel
    ranking: Ranking
    top: tuple[RankedConfiguration, ...]
    chosen: RankedConfiguration
    correlations: Correlations
    refined: Correlations | None
    best_by_range: dict[str, float]
    n_sweeps: int
    n_steps: int
    failed_steps: int
    timings: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "scales", _frozen(self.scales))

    @property
    def n_configurations(self) -> int:
        return int(self.ranking.log10_det.size)

    @property
    def n_identifiable(self) -> int:
        """Configurations whose FIM is positive definite."""
        return int(np.isfinite(self.ranking.log10_det).sum())

    @property
    def fim(self) -> np.ndarray:
        """FIM of the chosen configuration, physical units, shape (p, p)."""
        return self.correlations.fim

    @property
    def fim_inverse(self) -> np.ndarray:
        """Its inverse (Cramer-Rao covariance bound), physical units, shape (p, p)."""
        return self.correlations.fim_inverse

    @property
    def log10_det_offset(self) -> float:
        """``log10 det`` physical minus scaled: ``-2 sum log10 s`` (the same for all)."""
        return float(-2.0 * np.log10(np.abs(self.scales)).sum())

    def configuration(self, rank: int) -> RankedConfiguration:
        """The configuration at ``rank`` (1: the best) of the full ranking."""
        if not 1 <= rank <= self.n_configurations:
            raise ValueError(f"rank: must be in 1..{self.n_configurations}, got {rank}")
        flat = int(self.ranking.order[rank - 1])
        ld = float(self.ranking.log10_det[flat])
        return RankedConfiguration(
            rank, configuration_at(self.candidates, flat), ld + self.log10_det_offset, ld
        )

    def rank_of(self, configuration: Configuration) -> RankedConfiguration | None:
        """A configuration's place in the ranking (None if it is not a candidate)."""
        flat = configuration_index(self.candidates, configuration)
        if flat is None:
            return None
        rank = int(np.flatnonzero(self.ranking.order == flat)[0]) + 1
        return self.configuration(rank)

    def to_dict(self) -> dict:
        """JSON-friendly summary (the full ranking stays in ``ranking``)."""
        n = self.noise
        return {
            "parameters": list(self.parameters),
            "units": list(self.units),
            "scales": [float(s) for s in self.scales],
            "noise": {
                "relative": n.relative,
                "floor": n.floor,
                "sensor_floors": {str(k): v for k, v in n.sensor_floors.items()},
                "quantity": n.quantity,
                "unit": n.unit,
            },
            "n_configurations": self.n_configurations,
            "n_identifiable": self.n_identifiable,
            "top": [r.to_dict() for r in self.top],
            "chosen": self.chosen.to_dict(),
            "correlations": self.correlations.to_dict(),
            "refined": None if self.refined is None else self.refined.to_dict(),
            "best_log10_det_by_range": {k: _finite(v) for k, v in self.best_by_range.items()},
            "n_sweeps": self.n_sweeps,
            "n_steps": self.n_steps,
            "failed_steps": self.failed_steps,
            "timings_s": {k: round(v, 4) for k, v in self.timings.items()},
        }

    def to_json(self, **kwargs) -> str:
        """``json.dumps(self.to_dict(), **kwargs)``."""
        return json.dumps(self.to_dict(), **kwargs)

    def format_table(self) -> str:
        """Text report: the ranking as the paper's Table 4, FIM^-1 and correlation indices."""
        units = " x ".join(f"({u})" for u in self.units)
        lines = [
            f"{self.n_configurations} configurations ({self.n_identifiable} identifiable), "
            f"{self.n_sweeps} sweeps / {self.n_steps} steps, noise: {_noise_text(self.noise)}",
            "",
            f"{'No.':>3} {'actuator':>8}  {'levels [N]':<14}{'range [Hz]':<12}"
            f"{'sensors':<12}{'det(FIM)':>10} {'log10':>7}",
        ]
        for r in self.top:
            lines.append(_row(r))
        lines.append(f"det(FIM) in 1/({units})^2")
        lines.append("")
        lines.append(f"chosen: {self.chosen.configuration.describe()}")
        lines += _study_text(self.correlations, self.parameters, self.units)
        if self.refined is not None:
            lines.append("")
            lines += _study_text(self.refined, self.parameters, self.units, inverse=False)
        t = self.timings
        lines.append("")
        lines.append(
            "time: "
            + ", ".join(f"{k} {v:.2f} s" for k, v in t.items())
            + (f"; {self.failed_steps} unconverged steps" if self.failed_steps else "")
        )
        return "\n".join(lines)


def _noise_text(n: NoiseModel) -> str:
    return f"{100 * n.relative:g} % of |{n.quantity}| with a floor of {n.floor:g} {n.unit}"


def _row(r: RankedConfiguration) -> str:
    c = r.configuration
    levels = "[" + ", ".join(f"{v:g}" for v in c.levels_n) + "]"
    sensors = "[" + ", ".join(str(s) for s in c.sensors) + "]"
    rank = "-" if r.rank is None else str(r.rank)
    return (
        f"{rank:>3} {c.actuator:>8}  {levels:<14}{c.frequency_range.label:<12}{sensors:<12}"
        f"{r.det:>10.3g} {r.log10_det:>7.2f}"
    )


def _matrix_text(name: str, a: np.ndarray, labels: tuple[str, ...], fmt: str) -> list[str]:
    width = max(10, *(len(s) + 1 for s in labels))
    out = [f"{name}:", " " * width + "".join(f"{s:>{width}}" for s in labels)]
    for lab, row in zip(labels, a, strict=True):
        out.append(f"{lab:>{width}}" + "".join(f"{v:>{width}{fmt}}" for v in row))
    return out


def _study_text(c: Correlations, params, units, inverse: bool = True) -> list[str]:
    out = [f"step plan {c.step_plan} Hz ({c.n_steps} steps per level)"]
    if inverse:
        labels = tuple(f"{p} [{u}]" if u else p for p, u in zip(params, units, strict=True))
        out += _matrix_text("FIM^-1 (Cramer-Rao covariance bound)", c.fim_inverse, labels, ".3e")
        std = ", ".join(
            f"{p} {math.sqrt(v):.3g}" if v >= 0 else f"{p} -"
            for p, v in zip(params, np.diag(c.fim_inverse), strict=True)
        )
        out.append(f"standard deviations: {std}")
    out += _matrix_text("correlation indices (MAC, whitened Jacobian)", c.mac, params, ".3f")
    out += _matrix_text("correlation indices (MAC, FRF Jacobian)", c.mac_frf, params, ".3f")
    return out
