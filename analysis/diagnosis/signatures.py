"""Evidence in the data that points at physics: the signature tests of a stepped-sine file.

Each test compares the measurement with the model where it matters and says what it found
in numbers:

* **resonance shift with level**: the frequency of the largest fundamental response per level,
  measured and model; a measured shift the model does not have points at stiffening
  (upwards) or softening (downwards) beyond the model;
* **normalised peak height with level**: the peak of ``|Y_1| / |F_1|`` per level relative to
  the lowest level, measured and model; falling faster than the model's: added
  amplitude-dependent damping; rising: friction-like softening;
* **growth exponents**: ``d log|Y_k| / d log F_1`` of each order over the levels, gated at
  ``gate_sigma`` standard errors, measured and model (about 3 on the 3rd order for a cubic
  law, 2 on the 2nd for a quadratic one, 0 for Coulomb-like saturation);
* **distortion where the model predicts none**: steps where the model's 2nd and 3rd orders
  are those of its linear part but the measured ones differ by more than ``gate_sigma``;
* **linear misfit at low level**: the residual at the lowest level at steps where the model
  is linear (a linear error shows there, a nonlinear one does not).

The findings carry pointers to law families (:data:`FAMILIES`), which a diagnosis adds to the
candidates it verifies; they never decide on their own.

References
----------
G. Kerschen et al., MSSP 20 (2006) 505-592, sec. 3 (detection and characterisation:
homogeneity, resonance shift, harmonics).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from analysis.diagnosis.compare import Comparison
from analysis.measurement_file import SteppedSineData

__all__ = ["FAMILIES", "Evidence", "Finding", "find_signatures"]

#: Law families a finding can point at (element kinds and linear kinds).
FAMILIES = {
    "hardening": (
        "cubic_spring",
        "two_sided_gap",
        "gap_spring",
        "hertz_contact",
        "bilinear_spring",
    ),
    "softening": ("coulomb_friction", "cubic_spring", "joint_spring", "quadratic_spring"),
    "damping": ("quadratic_damper", "cubic_damper", "coulomb_friction", "linear_damper"),
    "even": ("quadratic_spring", "gap_spring", "hertz_contact", "bilinear_spring"),
    "linear": ("mass", "linear_spring", "joint_spring", "parameter", "linear_damper"),
}


@dataclass(frozen=True)
class Finding:
    """One signature test: its name, the numbers, a sentence and the families it points at."""

    name: str
    significant: bool
    text: str
    values: dict = field(default_factory=dict)
    points_at: tuple[str, ...] = ()


@dataclass
class Evidence:
    """All findings of a file against a model."""

    findings: list[Finding]

    @property
    def families(self) -> tuple[str, ...]:
        out: list[str] = []
        for f in self.findings:
            if f.significant:
                out += [p for p in f.points_at if p not in out]
        return tuple(out)

    def summary(self) -> str:
        lines = ["evidence in the data:"]
        lines += [f"  [{'x' if f.significant else ' '}] {f.text}" for f in self.findings]
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "families": list(self.families),
            "findings": [
                {
                    "name": f.name,
                    "significant": f.significant,
                    "text": f.text,
                    "values": f.values,
                    "points_at": list(f.points_at),
                }
                for f in self.findings
            ],
        }


def _levels(cmp: Comparison) -> list[float]:
    return sorted(set(cmp.level_n.tolist()))


def _peak(cmp: Comparison, which: np.ndarray, level: float, channel: int):
    """Frequency and height of the largest |H_1| at one level (finite values only)."""
    m = (cmp.level_n == level) & np.isfinite(which[:, channel, 0])
    if not m.any():
        return np.nan, np.nan
    h = np.abs(which[m, channel, 0])
    i = int(np.argmax(h))
    return float(cmp.frequency_hz[m][i]), float(h[i])


def _resonance(cmp: Comparison, channel: int) -> list[Finding]:
    levels = _levels(cmp)
    fm = np.array([_peak(cmp, cmp.measured, lv, channel)[0] for lv in levels])
    fp = np.array([_peak(cmp, cmp.predicted, lv, channel)[0] for lv in levels])
    hm = np.array([_peak(cmp, cmp.measured, lv, channel)[1] for lv in levels])
    hp = np.array([_peak(cmp, cmp.predicted, lv, channel)[1] for lv in levels])
    f = cmp.frequency_hz
    df = float(np.median(np.diff(np.unique(f)))) if np.unique(f).size > 1 else 0.1
    shift = (fm - fm[0]) - (fp - fp[0])
    sig = bool(np.nanmax(np.abs(shift)) > 1.5 * df) if len(levels) > 1 else False
    sign = float(np.nansum(shift))
    word = "upwards" if sign > 0 else "downwards"
    text = (
        f"resonance (largest fundamental response at {cmp.channels[channel]}): measured "
        + ", ".join(f"{v:.2f}" for v in fm)
        + " Hz, model "
        + ", ".join(f"{v:.2f}" for v in fp)
        + f" Hz at {', '.join(f'{lv:g}' for lv in levels)} N: the measurement moves "
        + (f"{abs(sign):.2f} Hz {word} beyond the model" if sig else "as the model does")
    )
    out = [
        Finding(
            "resonance_shift",
            sig,
            text,
            {"levels_n": levels, "measured_hz": fm.tolist(), "model_hz": fp.tolist()},
            ("hardening",) if sign > 0 else ("softening",),
        )
    ]
    rel_m, rel_p = hm / hm[0], hp / hp[0]
    ratio = rel_m / rel_p
    sig_h = bool(np.nanmax(np.abs(np.log(ratio))) > 0.05) if len(levels) > 1 else False
    trend = float(np.log(ratio[-1])) if len(levels) > 1 else 0.0
    text = (
        "normalised peak height relative to the lowest level: measured "
        + ", ".join(f"{v:.3f}" for v in rel_m)
        + ", model "
        + ", ".join(f"{v:.3f}" for v in rel_p)
        + (
            ": the measured peak falls faster than the model's (amplitude-dependent damping)"
            if sig_h and trend < 0
            else ": the measured peak rises against the model's (friction-like softening)"
            if sig_h
            else ": as the model"
        )
    )
    out.append(
        Finding(
            "peak_height",
            sig_h,
            text,
            {"measured": rel_m.tolist(), "model": rel_p.tolist()},
            ("damping",) if trend < 0 else ("softening",),
        )
    )
    return out


def _growth(cmp: Comparison, sigma: np.ndarray, gate: float) -> list[Finding]:
    """Median growth exponent of each order over the levels, measured and model."""
    levels = np.array(_levels(cmp))
    out: list[Finding] = []
    if levels.size < 2:
        return out
    freqs = np.unique(np.round(cmp.frequency_hz, 6))
    for k, order in enumerate(cmp.orders):
        em, ep = [], []
        for f in freqs:
            m = np.isclose(cmp.frequency_hz, f)
            if np.count_nonzero(m) < 2:
                continue
            lv = cmp.level_n[m]
            for c in range(len(cmp.channels)):
                ym = np.abs(cmp.measured[m, c, k])
                yp = np.abs(cmp.predicted[m, c, k])
                ok = (ym > gate * sigma[m, c, k]) & np.isfinite(yp) & (yp > 0)
                if np.count_nonzero(ok) < 2:
                    continue
                x = np.log(lv[ok])
                # the FRF is Y/F: growth of Y is 1 + growth of the FRF
                em.append(1 + np.polyfit(x, np.log(ym[ok]), 1)[0])
                ep.append(1 + np.polyfit(x, np.log(yp[ok]), 1)[0])
        if not em:
            continue
        gm, gp = float(np.median(em)), float(np.median(ep))
        sig = abs(gm - gp) > 0.3
        text = (
            f"order {order}: growth exponent d log|Y| / d log F {gm:.2f} measured, {gp:.2f} "
            f"model over {len(em)} gated (frequency, sensor) pairs"
            + (
                " -- the measurement grows faster"
                if sig and gm > gp
                else " -- the measurement grows slower"
                if sig
                else ""
            )
        )
        points: tuple[str, ...] = ()
        if sig and order == "2":
            points = ("even",)
        elif sig and order == "3":
            points = ("hardening",) if gm > gp else ("softening", "damping")
        out.append(
            Finding(
                f"growth_order_{order}",
                sig,
                text,
                {"order": order, "measured": gm, "model": gp, "n": len(em)},
                points,
            )
        )
    return out


def _distortion(cmp: Comparison, linear: np.ndarray, gate: float) -> Finding:
    """Higher orders measured beyond ``gate`` sigma where the model is linear."""
    r = np.abs(cmp.residual[:, :, 1:])
    m = linear[:, None, None] & np.isfinite(r)
    n_bad = int(np.count_nonzero((r > gate) & m))
    n = int(np.count_nonzero(m))
    sig = n > 0 and n_bad > 0.05 * n
    text = (
        f"distortion where the model predicts none: {n_bad} of {n} higher-order values at "
        f"steps where the model is linear exceed {gate:g} standard errors"
    )
    return Finding("distortion", sig, text, {"n_exceeding": n_bad, "n": n}, ("hardening", "even"))


def _linear_misfit(cmp: Comparison, linear: np.ndarray) -> Finding:
    lowest = min(_levels(cmp))
    m = (cmp.level_n == lowest) & linear
    z = np.abs(cmp.residual[m][:, :, 0]) ** 2
    z = z[np.isfinite(z)]
    rms = float(np.sqrt(z.mean())) if z.size else np.nan
    sig = bool(z.size and rms > 2.0)
    text = (
        f"linear misfit at the lowest level ({lowest:g} N, {int(m.sum())} steps where the model "
        f"is linear): fundamental rms {rms:.2f} standard errors"
        + (" -- the linear model is in error" if sig else "")
    )
    return Finding(
        "linear_misfit", sig, text, {"rms_sigma": rms, "n_steps": int(m.sum())}, ("linear",)
    )


def find_signatures(
    cmp: Comparison,
    data: SteppedSineData,
    sigma: np.ndarray,
    linear_steps: np.ndarray,
    *,
    gate_sigma: float = 5.0,
) -> Evidence:
    """Run every signature test.

    Parameters
    ----------
    cmp : Comparison
        The model against the file (:func:`analysis.diagnosis.compare.compare`).
    data : SteppedSineData
    sigma : ndarray, shape (n_steps, n_channels, n_orders)
        Standard errors of the measured FRFs.
    linear_steps : ndarray of bool, shape (n_steps,)
        Steps where the model's nonlinear elements exert no force (its response is linear).
    gate_sigma : float
        Orders below this many standard errors are not read.
    """
    del data
    channel = int(np.nanargmax(np.nanmax(np.abs(cmp.measured[:, :, 0]), axis=0)))
    findings = _resonance(cmp, channel)
    findings += _growth(cmp, sigma, gate_sigma)
    findings.append(_distortion(cmp, linear_steps, gate_sigma))
    findings.append(_linear_misfit(cmp, linear_steps))
    return Evidence(findings)
