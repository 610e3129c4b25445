"""The measurement that separates tied candidates, written as a test plan.

:func:`analysis.diagnosis.discriminate.discriminate` names the configuration (sensor, level,
frequency range) where the tied candidates' predictions differ most; this module writes it as a
stepped-sine plan in the rig's plan file format (``rig/plans/*.toml``, documented in
``docs/acquisition.md``), so the rig can run it and the diagnosis rank again on both files. The plan
keeps the file's drive (actuator, force orders and their relative amplitudes) and sensors, adds
the proposed sensor, and steps the proposed range at the proposed level; every other setting is
the plan format's default. The analysis writes the file without importing the rig; the rig's
tests read it back with the rig's own reader.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from analysis.measurement_file import SteppedSineData

__all__ = ["Separation", "rank_on_separating_run", "separating_plan", "write_separating_plan"]


def separating_plan(recommendation: dict, data: SteppedSineData, name: str = "separate") -> dict:
    """The plan document (a dict for ``tomli_w``) of a discrimination's best configuration.

    Parameters
    ----------
    recommendation : dict
        :func:`~analysis.diagnosis.discriminate.discriminate`'s result (``best`` with
        ``sensor``, ``level_n``, ``start_hz``, ``stop_hz``, ``step_hz``; ``candidates``).
    data : SteppedSineData
        The file the tie came from (its drive, orders and sensors are kept).
    name : str
        The plan's name.
    """
    best = recommendation.get("best")
    missing = [k for k in ("sensor", "level_n", "start_hz", "stop_hz", "step_hz") if k not in best]
    if missing:
        raise ValueError(f"recommendation's best configuration lacks {', '.join(missing)}")
    orders = [Fraction(o).limit_denominator(1000) for o in data.orders]
    one = Fraction(1)
    if one not in orders:
        raise ValueError("the file's force has no fundamental (order 1) to scale the plan by")
    targets = np.asarray(data.force_targets[0])
    ratio = targets / targets[orders.index(one)]  # the plan gives amplitudes relative to it
    points = sorted({int(ch.point) for ch in data.channels} | {int(best["sensor"])})
    tied = "; ".join(recommendation.get("candidates", []))
    doc: dict[str, Any] = {
        "name": name,
        "kind": "stepped-sine",
        "description": (
            f"separates {tied}: point {best['sensor']}, {best['level_n']:g} N, "
            f"{best['start_hz']:g}-{best['stop_hz']:g} Hz"
        ),
        "points": points,
        "excitation": {
            "orders": [int(o) if o.denominator == 1 else str(o) for o in orders],
            "relative_amplitudes": [float(abs(r)) for r in ratio],
            "phases_deg": [float(np.degrees(np.angle(r))) for r in ratio],
            "levels_n": [float(best["level_n"])],
        },
        # the loop check where every sensor responds (the range's first step may lie below
        # the structure's modes, where an accelerometer hardly moves at the check's level)
        **_pretest(best),
        "frequencies": {
            "direction": "up",
            "ranges": [
                {
                    "start_hz": float(best["start_hz"]),
                    "stop_hz": float(best["stop_hz"]),
                    "step_hz": float(best["step_hz"]),
                }
            ],
        },
    }
    return doc


def _pretest(best: dict) -> dict:
    """The plan's ``[pretest]`` table: where the loop check runs (the recommendation's
    ``loop_check_hz``; its drive stays the plan format's)."""
    if not np.isfinite(best.get("loop_check_hz", np.nan)):
        return {}
    return {"pretest": {"loop_check_frequency_hz": float(best["loop_check_hz"])}}


def write_separating_plan(
    path: str | Path, recommendation: dict, data: SteppedSineData, name: str | None = None
) -> Path:
    """Write :func:`separating_plan` to ``path`` (TOML); returns the path."""
    path = Path(path)
    doc = separating_plan(recommendation, data, name or path.stem)
    header = (
        "# The measurement that separates the tied candidates of a diagnosis: run it with\n"
        "# `python -m rig separate RUN --model MODEL` (or `python -m rig run PLAN`).\n"
    )
    path.write_text(header + tomli_w.dumps(doc))
    return path


@dataclass(frozen=True)
class Separation:
    """The tied candidates ranked again on the separating run.

    Attributes
    ----------
    ranking : list of dict
        Per candidate, best first: ``label``, ``chi2`` (on the steps every candidate converged
        at), ``delta_chi2`` (to the best) and ``rms_over_noise``.
    tie_chi2 : float
        The candidates within this of the best remain tied.
    """

    ranking: list[dict]
    tie_chi2: float

    @property
    def tied(self) -> list[str]:
        """The labels still tied with the best (the best alone when the run separated them)."""
        return [r["label"] for r in self.ranking if r["delta_chi2"] <= self.tie_chi2]

    @property
    def resolved(self) -> bool:
        return len(self.tied) == 1

    def summary(self) -> str:
        lines = ["the tied candidates on the separating run (fitted on the first run):"]
        for r in self.ranking:
            lines.append(
                f"  {r['label']}: residual {r['rms_over_noise']:.3g} x noise, "
                f"delta chi-square {r['delta_chi2']:.1f}"
            )
        if self.resolved:
            lines.append(f"resolved: {self.tied[0]}")
        else:
            lines.append(f"still tied within {self.tie_chi2:g}: " + "; ".join(self.tied))
        return "\n".join(lines)


def rank_on_separating_run(group, data: SteppedSineData, tie_chi2: float) -> Separation:
    """Rank tied candidates by how well each predicts the separating run.

    Each candidate keeps the parameters its verification fitted on the first run, so the
    second run is a prediction: the difference of two candidates' chi-squares on it is twice
    their log-likelihood ratio, the scale of the BIC the tie was judged on (no parameter is
    fitted, so none is charged). Scored on the steps every candidate converged at.

    Parameters
    ----------
    group : sequence of RankedCandidate
        The tied group (:attr:`Diagnosis.group`).
    data : SteppedSineData
        The separating run.
    tie_chi2 : float
        Candidates within this of the best stay tied (the diagnosis's ``tie_bic``).
    """
    from analysis.diagnosis.compare import compare
    from analysis.model import Model

    if len(group) < 2:
        raise ValueError("ranking on a separating run needs at least two tied candidates")
    residuals = []
    for g in group:
        model = Model.from_toml_text(g.verified.model_toml, f"<{g.candidate.label}>")
        residuals.append(compare(model, data).residual)
    common = np.logical_and.reduce([np.isfinite(r) for r in residuals])
    if not common.any():
        raise RuntimeError("no step of the separating run converged for every tied candidate")
    chi2 = [float((np.abs(r[common]) ** 2).sum()) for r in residuals]
    best = min(chi2)
    n = int(common.sum())
    ranking = sorted(
        (
            {
                "label": g.candidate.label,
                "chi2": c,
                "delta_chi2": c - best,
                "rms_over_noise": float(np.sqrt(c / n)),
            }
            for g, c in zip(group, chi2, strict=True)
        ),
        key=lambda r: r["chi2"],
    )
    return Separation(ranking, tie_chi2)
