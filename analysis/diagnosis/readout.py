"""What the data show about a missing law: the describing function of the force at a location.

When no law of the element library explains the misfit, the screen's force estimate
(:meth:`~analysis.diagnosis.screen.Screen.states`) still says how the missing force behaves.
At one location, per measured step, it gives the relative displacement ``x`` and the force the
data put there at every measured order. The element's *restoring* force ``r = -g`` (``g`` the
force on the structure, the sign of :mod:`analysis.elements`) is read on its first harmonic by
its describing function (equivalent linearisation)

    R_1 / X_1 = k_eq + i omega c_eq,        x(t) = Re(X_1 e^{i omega t}),

so a spring ``r = k x`` gives ``k_eq = k`` and a damper ``r = c dx/dt`` gives ``c_eq = c``,
against the amplitude ``A = |X_1|`` (m, or rad in a rotation). The describing functions of the
standard laws, for ``x = A cos(omega t)`` (Gelb and Vander Velde, "Multiple-Input Describing
Functions and Nonlinear System Design", McGraw-Hill 1968, ch. 2; Worden and Tomlinson,
"Nonlinearity in Structural Dynamics", IOP 2001, ch. 3), are what the reading is argued from:

- linear spring ``k x``: ``k_eq = k`` (no change with ``A``);
- cubic spring ``k3 x^3``: ``k_eq = k + 3/4 k3 A^2``, slope 2 of ``k_eq - k_eq(0)`` against
  ``A`` (hardening for ``k3 > 0``, softening, ``k_eq`` falling, for ``k3 < 0``);
- ``k2 x |x|``: ``k_eq = 8/(3 pi) k2 A``, slope 1;
- one-sided stop (clearance ``d``): ``k_eq`` rises from 0 once ``A > d``, steeply, then
  flattening; the force has even orders (it is not odd in ``x``);
- viscous damper ``c v``: ``c_eq = c`` (slope 0);
- quadratic damper ``c2 v |v|``: ``c_eq = 8/(3 pi) c2 omega A``, slope 1 of ``c_eq``;
- cubic damper ``c3 v^3``: ``c_eq = 3/4 c3 omega^2 A^2``, slope 2;
- Coulomb friction ``F_s sgn(v)``: ``c_eq = 4 F_s/(pi omega A)``, slope -1 (``omega c_eq A``,
  the dissipative force, is ``4 F_s/pi`` whatever the amplitude);
- Jenkins element (a spring ``k_t`` in series with a slider ``F_s``): stuck below
  ``a = F_s/k_t`` (``k_eq = k_t``, no dissipation); slipping above, ``k_eq`` falls towards 0
  and ``omega c_eq = 4 F_s (A - a)/(pi A^2)`` rises from 0, peaks at ``A = 2a`` and falls as
  ``A^-1`` (Coulomb's slope).

An Iwan joint (parallel Jenkins elements) slips gradually: its energy per cycle
``E = pi omega c_eq A^2`` grows as ``A^2`` to ``A^3`` at micro-slip (``omega c_eq`` rising as
``A^0`` to ``A^1`` while ``k_eq`` falls) and as ``A`` at macro-slip (D. J. Segalman, "A
four-parameter Iwan model for lap-type joints", J. Appl. Mech. 72 (2005) 752-760).

The reading fits ``k_eq = k_0 + a A^p`` over every step (``p > 0``: ``k_0`` is the value at
the smallest amplitudes, and a calibration that absorbed part of the missing stiffness into the
model's own parameters leaves an offset there) and ``c_eq = b A^q`` (with a constant ``c_0``
only where the data ask for one) over the upper half of the amplitudes, or above the
dissipation's peak where it has one: a law's own behaviour shows at the largest amplitudes,
where a friction law's regularisation or stick and a small constant part weigh least. Each is
a weighted least-squares fit with the exponent profiled; its uncertainty is where the profiled
chi-square rises by its scale (1, or the points' spread about the fit where that exceeds their
noise). A change with the amplitude counts only where it lowers the chi-square by more than
nine times that scale (three standard errors; for the damping, over the upper half or, with
more leverage, over every step), a slope only where its uncertainty is at most
:data:`SLOPE_RESOLVED`. The damping is fitted as a law of the velocity amplitude (``c_eq`` a
function of ``omega A``: a damper) and as a rate-independent one (``omega c_eq`` a function of
``A``: friction, hysteresis); the better is kept, and named where the data tell them apart (a
resonance sweep varies ``omega`` little, so often they do not). Binned by amplitude, a
dissipation ``omega c_eq`` that rises and then falls is a stick-slip joint's.

Each step's ``k_eq``, ``c_eq`` are a ratio of two estimates from the same data. Their error is
taken from ``r_1 - D x_1``, linear in the data, at the binned describing function ``D`` (at a
step's own ratio it would vanish where the step's force is mostly noise, which would weigh the
noisiest steps most), and a step is read only where its displacement stands
:data:`SNR_MIN` standard errors above its noise.

The force's orders above the first that its first-harmonic describing function does not
account for (``R_h - (k_eq + i h omega c_eq) X_h``: a law linear at each amplitude leaves none)
are its distortion: even orders mean an asymmetric law (a one-sided stop, a quadratic spring),
odd orders a symmetric one whose shape is not a straight line (hardening, softening, a
slider's switch).

Limits: the force is seen only through the sensors (the screen's weighted least squares; at a
DOF no sensor measures, through the structure), so its noise grows where the location moves
little; only the recorded orders are seen (the loops ``f(x)``, ``f(v)`` are rebuilt from them,
without the mean, which accelerometers do not measure, and without the orders above the last
recorded one); a law with memory (a joint's stick-slip) is read at the states the test reached.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
from scipy.optimize import minimize_scalar

from analysis.diagnosis.candidates import Location, default_locations

__all__ = [
    "KINDS",
    "SLOPE_RESOLVED",
    "AmplitudeFit",
    "Bins",
    "ForceReadout",
    "LawReading",
    "amplitude_bins",
    "describing_function",
    "fit_amplitude_law",
    "read_law",
    "read_missing_force",
]

#: A slope is named only when its standard uncertainty is at most this.
SLOPE_RESOLVED = 0.3
#: A change with the amplitude is claimed when it lowers the chi-square by more than this many
#: times its scale (three standard errors).
CHANGE_CHI2 = 9.0
#: A measured slope is read as a standard law's when it lies within this of the law's (or two
#: standard uncertainties, whichever is larger): a sweep spans one or two decades of
#: amplitude, and a real law is only near a power law over it.
SLOPE_MATCH = 0.25
#: Relative precision taken for describing functions given without standard errors.
EXACT = 1e-9
#: Exponents searched by the profile (a damping's: friction's is -1).
EXPONENT_RANGE = (-3.0, 4.0)
#: Exponents of a stiffness change, measured from the smallest amplitudes' value: positive.
STIFFNESS_EXPONENTS = (0.1, 4.0)
#: Groups of steps by amplitude for the binned values the text quotes and the peak test.
N_BINS = 8
#: Distortion is named only from this share of the first harmonic (a smaller one is the
#: model's own error as much as the law's).
DISTORTION_SHARE = 0.1
#: A step is read where its displacement stands this many standard errors above its noise
#: (the amplitude is the fits' abscissa).
SNR_MIN = 3.0
#: Loops drawn: the largest-amplitude step of at most this many levels.
N_LOOPS = 4
#: Samples of a loop over its period.
LOOP_SAMPLES = 256


# -- the describing function -------------------------------------------------------------------
def describing_function(
    x1: np.ndarray, r1: np.ndarray, omega: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(k_eq, c_eq)`` of first-harmonic phasors: displacement ``x1`` (m or rad), restoring
    force ``r1`` (N or N m, opposing the motion: ``r = k x + c v``), angular frequency
    ``omega`` (rad/s); ``k_eq = Re(r1/x1)``, ``c_eq = Im(r1/x1)/omega``."""
    d = np.asarray(r1) / np.asarray(x1)
    return d.real, d.imag / np.asarray(omega)


# -- fits of one quantity against the amplitude ------------------------------------------------
@dataclass
class AmplitudeFit:
    """``y = y0 + a (A/A_ref)^p (omega/omega_ref)^(s)``, fitted by weighted least squares with
    ``p`` profiled (``s`` is 0, ``p`` or -1: :func:`fit_amplitude_law`).

    Attributes
    ----------
    y0, a : float
        Offset (the value at vanishing amplitude for ``p > 0``) and coefficient.
    p, sigma_p : float
        Exponent (the log-log slope of ``y - y0`` against ``A``) and its standard uncertainty
        (``inf`` where the profile does not close within :data:`EXPONENT_RANGE`).
    a_ref, omega_ref : float
    rate : float or str
        ``s``: ``0.0``, ``"p"`` (a function of the velocity amplitude) or ``-1.0``.
    chi2, chi2_const : float
        Chi-square of the fit and of a constant, over the scale ``scale`` (1 where the points
        scatter as their standard errors say, more where they scatter more).
    n : int
    span : (float, float)
        The smallest and largest amplitude fitted.
    """

    y0: float
    a: float
    p: float
    sigma_p: float
    a_ref: float
    omega_ref: float
    rate: float | str
    chi2: float
    chi2_const: float
    scale: float
    n: int
    span: tuple[float, float] = (math.nan, math.nan)

    @property
    def changes(self) -> bool:
        """The quantity changes with the amplitude beyond its noise."""
        return bool(self.chi2_const - self.chi2 > CHANGE_CHI2 * self.scale)

    @property
    def resolved(self) -> bool:
        """The slope is resolved (:data:`SLOPE_RESOLVED`)."""
        return bool(self.changes and self.sigma_p <= SLOPE_RESOLVED)

    def at(self, A, omega=None) -> np.ndarray:
        """The fitted value at amplitudes ``A`` (and angular frequencies ``omega``)."""
        A = np.asarray(A, float)
        w = self.omega_ref if omega is None else np.asarray(omega, float)
        s = self.p if self.rate == "p" else float(self.rate)
        return self.y0 + self.a * (A / self.a_ref) ** self.p * (w / self.omega_ref) ** s

    def to_json(self) -> dict:
        return {
            "offset": self.y0,
            "coefficient": self.a,
            "amplitude_ref": self.a_ref,
            "omega_ref_rad_s": self.omega_ref,
            "slope": self.p if self.changes else None,
            "slope_sigma": self.sigma_p if self.changes else None,
            "rate_exponent": self.rate,
            "changes": self.changes,
            "resolved": self.resolved,
            "chi2": self.chi2,
            "chi2_constant": self.chi2_const,
            "scale": self.scale,
            "n": self.n,
            "amplitude_span": list(self.span),
        }


def _columns(A, omega, p, rate, a_ref, w_ref) -> np.ndarray:
    s = p if rate == "p" else float(rate)
    return (A / a_ref) ** p * (omega / w_ref) ** s


def fit_amplitude_law(
    A: np.ndarray,
    y: np.ndarray,
    sigma: np.ndarray | None = None,
    omega: np.ndarray | None = None,
    rate: float | str = 0.0,
    *,
    offset: bool = True,
    exponents: tuple[float, float] = EXPONENT_RANGE,
) -> AmplitudeFit:
    """Fit ``y = y0 + a (A/A_ref)^p (omega/omega_ref)^s`` (see :class:`AmplitudeFit`).

    ``sigma`` are the standard errors of ``y`` (``None``: equal, the scale from the spread).
    The exponent's uncertainty is where the profiled chi-square rises by the scale.
    """
    A = np.asarray(A, float)
    y = np.asarray(y, float)
    n = A.size
    w_all = np.ones(n) if omega is None else np.asarray(omega, float)
    if n < 4:
        raise ValueError(f"an amplitude law needs 4 or more points, got {n}")
    s = np.ones(n) if sigma is None else np.maximum(np.asarray(sigma, float), 1e-300)
    a_ref = float(np.exp(np.mean(np.log(A))))
    w_ref = float(np.exp(np.mean(np.log(w_all))))
    wy = y / s
    const = np.ones(n) / s
    c0 = float(wy @ const / (const @ const))
    chi2_const = float(np.sum((wy - c0 * const) ** 2))

    def solve(p: float):
        col = _columns(A, w_all, p, rate, a_ref, w_ref) / s
        M = np.stack([const, col], axis=1) if offset else col[:, None]
        coef, *_ = np.linalg.lstsq(M, wy, rcond=None)
        r = wy - M @ coef
        return float(r @ r), (coef if offset else np.array([0.0, coef[0]]))

    lo, hi = exponents
    grid = np.arange(lo, hi + 1e-9, 0.05)
    grid = grid[np.abs(grid) > 0.075]  # p = 0 duplicates the offset
    prof = np.array([solve(p)[0] for p in grid])
    i = int(np.argmin(prof))
    a_, b_ = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    opt = minimize_scalar(
        lambda p: solve(p)[0], bounds=(a_, b_), method="bounded", options={"xatol": 1e-7}
    )
    p_hat = float(opt.x) if opt.fun <= prof[i] else float(grid[i])
    chi2, coef = solve(p_hat)
    dof = max(n - 2 - int(offset), 1)
    if sigma is None:
        # no standard errors: the scale is the spread about the fit (a floor for exact data)
        scale = max(chi2 / dof, 1e-24 * float(np.mean(y**2)) + 1e-300)
    else:
        scale = max(chi2 / dof, 1.0)
    sigma_p = _profile_width(solve, grid, prof, p_hat, chi2 + scale)
    return AmplitudeFit(
        float(coef[0]),
        float(coef[1]),
        p_hat,
        sigma_p,
        a_ref,
        w_ref,
        rate,
        chi2,
        chi2_const,
        scale,
        n,
        (float(A.min()), float(A.max())),
    )


def _profile_width(solve, grid, prof, p_hat: float, level: float) -> float:
    """Half the width of the exponent interval where the profiled chi-square stays below
    ``level``; ``inf`` where it does not close on a side."""
    ends = []
    for side in (-1, 1):
        idx = np.flatnonzero((prof > level) & (np.sign(grid - p_hat) == side))
        if idx.size == 0:
            return math.inf
        j = idx[np.argmin(np.abs(grid[idx] - p_hat))]
        a, b = (grid[j], p_hat) if side < 0 else (p_hat, grid[j])
        for _ in range(60):  # bisection on the crossing
            m = 0.5 * (a + b)
            inside = solve(m)[0] <= level
            if side < 0:
                a, b = (a, m) if inside else (m, b)
            else:
                a, b = (m, b) if inside else (a, m)
            if abs(b - a) < 1e-9:
                break
        ends.append(0.5 * (a + b))
    return 0.5 * (ends[1] - ends[0])


# -- the reading -------------------------------------------------------------------------------
@dataclass
class Bins:
    """Weighted means of a quantity over the steps grouped by amplitude (equal counts), with
    standard errors widened by the spread within each group where it exceeds the noise."""

    A: np.ndarray
    y: np.ndarray
    sigma: np.ndarray

    def to_json(self) -> dict:
        return {"amplitude": self.A.tolist(), "mean": self.y.tolist(), "sigma": self.sigma.tolist()}


def amplitude_bins(A, y, sigma, n_bins: int = N_BINS) -> Bins:
    """:class:`Bins` of ``y`` (standard errors ``sigma``) over ``min(n_bins, n // 4)`` groups
    of the amplitudes ``A`` (two at least)."""
    A, y, sigma = (np.asarray(v, float) for v in (A, y, sigma))
    order = np.argsort(A)
    count = max(min(n_bins, A.size // 4), min(2, A.size))
    groups = [g for g in np.array_split(order, count) if g.size]
    out_a, out_y, out_s = [], [], []
    for g in groups:
        w = 1.0 / np.maximum(sigma[g], 1e-300) ** 2
        m = float(np.sum(w * y[g]) / w.sum())
        spread = float(np.sum(w * (y[g] - m) ** 2)) / max(g.size - 1, 1)
        out_a.append(float(np.exp(np.mean(np.log(A[g])))))
        out_y.append(m)
        out_s.append(math.sqrt(max(spread, 1.0) / w.sum()))
    return Bins(np.array(out_a), np.array(out_y), np.array(out_s))


def _near(fit: AmplitudeFit | None, target: float) -> bool:
    return (
        fit is not None
        and fit.resolved
        and abs(fit.p - target) <= max(SLOPE_MATCH, 2 * fit.sigma_p)
    )


#: What each kind of reading is, in words.
KINDS = {
    "stick_slip": "a joint that sticks and slips (Jenkins/Iwan)",
    "coulomb_friction": "dry (Coulomb) friction",
    "quadratic_damper": "a quadratic damper",
    "cubic_damper": "a cubic damper",
    "amplitude_damping": "a damping that changes with the amplitude",
    "asymmetric_softening": "an asymmetric law whose stiffness falls (a clearance or a crack "
    "that opens on one side)",
    "one_sided_stop": "a one-sided stop or contact",
    "cubic_hardening": "a cubic hardening spring",
    "hardening": "a hardening spring",
    "cubic_softening": "a cubic softening spring",
    "softening": "a softening spring",
    "no_change": "a linear spring and damper, or a law below the noise (nothing changes with "
    "the amplitude beyond it)",
}


@dataclass
class LawReading:
    """What the describing functions of a force say about its law (:func:`read_law`).

    Attributes
    ----------
    kind : str
        A key of :data:`KINDS`.
    stiffness : AmplitudeFit
        ``k_eq = k_0 + a A^p`` over every step (``p > 0``: ``k_0`` the smallest amplitudes').
    damping : AmplitudeFit
        ``c_eq = b A^q`` over the upper half of the amplitudes, or above the dissipation's
        peak where it has one; as a function of the velocity amplitude or rate-independent,
        whichever fits better.
    damping_form : str
        ``"velocity"`` (a damper), ``"amplitude"`` (friction, hysteresis) or ``"either"`` (the
        data do not tell them apart).
    peak : float or None
        Amplitude where the dissipation ``omega c_eq`` peaks inside the range (rises, then
        falls, each by three standard errors of the binned means), else None.
    damping_whole : AmplitudeFit
        ``c_eq`` over every step: whether it changes at all where the upper half alone spans
        too little of the amplitude to say.
    below_peak : AmplitudeFit or None
        The dissipation ``omega c_eq`` against the amplitude below the peak: the energy per
        cycle ``pi omega c_eq A^2`` grows as ``A^(2 + slope)``.
    k_bins, c_bins, h_bins : Bins
        ``k_eq``, ``c_eq`` and ``omega c_eq`` binned by amplitude: what the text quotes.
    even_share, odd_share : float
        Distortion of the force in even and odd orders over its first harmonic (median over the
        upper half of the amplitudes); NaN where no such order was recorded.
    even_seen, odd_seen : bool
        Above the noise and at least :data:`DISTORTION_SHARE`.
    """

    kind: str
    stiffness: AmplitudeFit
    damping: AmplitudeFit
    damping_form: str
    peak: float | None
    damping_whole: AmplitudeFit
    below_peak: AmplitudeFit | None
    k_bins: Bins
    c_bins: Bins
    h_bins: Bins
    even_share: float = math.nan
    odd_share: float = math.nan
    even_seen: bool = False
    odd_seen: bool = False

    @property
    def description(self) -> str:
        return KINDS[self.kind]

    @property
    def stiffness_change(self) -> float:
        """Binned ``k_eq`` at the largest amplitudes minus at the smallest (0 unless the fit
        finds a change)."""
        if not self.stiffness.changes:
            return 0.0
        return float(self.k_bins.y[-1] - self.k_bins.y[0])

    def to_json(self) -> dict:
        return {
            "kind": self.kind,
            "description": self.description,
            "stiffness": self.stiffness.to_json(),
            "damping": self.damping.to_json(),
            "damping_form": self.damping_form,
            "damping_whole_range": self.damping_whole.to_json(),
            "energy_exponent_below_peak": (
                2 + self.below_peak.p
                if self.below_peak is not None and self.below_peak.resolved
                else None
            ),
            "dissipation_peak_amplitude": self.peak,
            "stiffness_bins": self.k_bins.to_json(),
            "damping_bins": self.c_bins.to_json(),
            "even_share": _finite(self.even_share),
            "odd_share": _finite(self.odd_share),
            "even_seen": self.even_seen,
            "odd_seen": self.odd_seen,
        }


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def read_law(
    A: np.ndarray,
    omega: np.ndarray,
    k_eq: np.ndarray,
    c_eq: np.ndarray,
    sigma_k: np.ndarray | None = None,
    sigma_c: np.ndarray | None = None,
    *,
    distortion: dict | None = None,
) -> LawReading:
    """Read a law from its describing functions at amplitudes ``A`` and angular frequencies
    ``omega`` (the module notes): the fits, the peak of the dissipation, the kind.

    ``sigma_k``, ``sigma_c``: standard errors (``None``: exact values, good to :data:`EXACT`
    of the largest ``|k_eq + i omega c_eq|``). ``distortion``: ``{"even": (share, seen),
    "odd": (share, seen)}``.
    """
    A, omega = np.asarray(A, float), np.asarray(omega, float)
    k_eq, c_eq = np.asarray(k_eq, float), np.asarray(c_eq, float)
    if sigma_k is None or sigma_c is None:
        # exact values (a law's describing function): good to rounding, relative to the
        # largest force per displacement; the fits' scale then follows their spread
        tol = EXACT * float(np.max(np.hypot(k_eq, omega * c_eq)))
        sigma_k = np.full(A.size, tol) if sigma_k is None else np.asarray(sigma_k, float)
        sigma_c = tol / omega if sigma_c is None else np.asarray(sigma_c, float)
    stiff = fit_amplitude_law(A, k_eq, sigma_k, exponents=STIFFNESS_EXPONENTS)
    h_bins = amplitude_bins(A, c_eq * omega, sigma_c * omega)
    peak = _peak(h_bins)
    # the damping's slope where the law's own behaviour shows: above the dissipation's peak,
    # else over the upper half of the amplitudes (a friction law's regularisation or stick,
    # and a small constant part, weigh at the smallest)
    upper = A >= (np.median(A) if peak is None else peak)
    if upper.sum() < 4:
        upper = A >= np.sort(A)[-4]
    fits = [
        _damping_fit(A[upper], c_eq[upper], sigma_c[upper], omega[upper], rate)
        for rate in ("p", -1.0)
    ]
    damp = min(fits, key=lambda f: f.chi2)
    form = "either"
    if damp.changes and abs(fits[0].chi2 - fits[1].chi2) > CHANGE_CHI2 * damp.scale:
        form = "velocity" if damp is fits[0] else "amplitude"
    below = None
    if peak is not None and np.sum(A <= peak) >= 4:
        # energy per cycle pi omega c_eq A^2 below the peak: A^2 to A^3 at a joint's micro-slip
        low = A <= peak
        below = fit_amplitude_law(A[low], (c_eq * omega)[low], (sigma_c * omega)[low], offset=False)
    # the whole range: more leverage, for whether (not how) the damping changes
    whole = min(
        (_damping_fit(A, c_eq, sigma_c, omega, rate) for rate in ("p", -1.0)),
        key=lambda f: f.chi2,
    )
    dist = distortion or {}
    even, even_seen = dist.get("even", (math.nan, False))
    odd, odd_seen = dist.get("odd", (math.nan, False))
    reading = LawReading(
        "no_change",
        stiff,
        damp,
        form,
        peak,
        whole,
        below,
        amplitude_bins(A, k_eq, sigma_k),
        amplitude_bins(A, c_eq, sigma_c),
        h_bins,
        even,
        odd,
        even_seen,
        odd_seen,
    )
    reading.kind = _kind(reading)
    return reading


def _damping_fit(A, c, sigma, omega, rate) -> AmplitudeFit:
    """``c_eq = b A^q``, or ``c_0 + b A^q`` where the constant part (a viscous part, or what
    the calibration left in the model's damping) lowers the chi-square by more than
    :data:`CHANGE_CHI2` times its scale: a constant that the data do not ask for would trade
    with the exponent."""
    bare = fit_amplitude_law(A, c, sigma, omega, rate=rate, offset=False)
    if A.size < 6:
        return bare
    full = fit_amplitude_law(A, c, sigma, omega, rate=rate)
    return full if bare.chi2 - full.chi2 > CHANGE_CHI2 * full.scale else bare


def _peak(h: Bins) -> float | None:
    """The amplitude where the binned dissipation ``omega c_eq`` rises and then falls, each by
    three standard errors, or None."""
    if h.y.size < 3:
        return None
    i = int(np.argmax(h.y))
    if not 0 < i < h.y.size - 1:
        return None
    rise = h.y[i] - h.y[0] > 3 * math.hypot(h.sigma[i], h.sigma[0])
    fall = h.y[i] - h.y[-1] > 3 * math.hypot(h.sigma[i], h.sigma[-1])
    return float(h.A[i]) if rise and fall else None


def _kind(r: LawReading) -> str:
    """The kind the fits point at, argued from the standard describing functions (module
    notes): a stiffness that falls while the damping changes is a joint that slips; a damping
    slope of -1 is friction, 1 or 2 a power-law damper; a rising stiffness with even orders a
    one-sided stop, with a slope of 2 a cubic spring."""
    k, c = r.stiffness, r.damping
    dk = r.stiffness_change
    if dk < 0 and (r.peak is not None or c.changes or r.damping_whole.changes):
        return "stick_slip"
    if _near(c, -1.0):
        return "coulomb_friction"
    if r.peak is None and dk == 0:
        if _near(c, 1.0):
            return "quadratic_damper"
        if _near(c, 2.0):
            return "cubic_damper"
    if dk > 0:
        if r.even_seen:
            return "one_sided_stop"
        return "cubic_hardening" if _near(k, 2.0) else "hardening"
    if dk < 0:
        if r.even_seen:
            return "asymmetric_softening"
        return "cubic_softening" if _near(k, 2.0) else "softening"
    if c.changes or r.damping_whole.changes:
        return "amplitude_damping"
    return "no_change"


# -- the read-out at a location of a screen ----------------------------------------------------
@dataclass
class ForceReadout:
    """The missing force at one location, read from a screen's force estimate.

    Attributes
    ----------
    location : str
        The location asked for; ``read_at`` where it was read (a group's member the sensors
        see most), ``note`` why it differs.
    rotation : bool
        A rotation (rad, N m) rather than a translation (m, N).
    stiffness_offset : float
        Added to every ``k_eq``: a joint's anchor spring in the screen's model
        (:data:`~analysis.diagnosis.screen.JOINT_ANCHOR`), so ``k_eq`` is the joint's own
        stiffness; 0 elsewhere, where ``k_eq`` is the stiffness the model lacks.
    amplitude, omega, level_n, k_eq, c_eq, sigma_k, sigma_c, even_share, odd_share : ndarray
        Per measured step: ``|X_1|`` (m or rad), the drive's angular frequency (rad/s), the
        file's force level (N), the describing function (N/m, N s/m; N m/rad, N m s/rad) and their
        standard errors, the distortion shares.
    seen : ndarray of bool
        Steps whose displacement stands :data:`SNR_MIN` standard errors above its noise: the
        only ones read.
    reading : LawReading or None
        None where fewer than four steps are seen.
    loops : list of dict
        One period of ``x``, ``v`` and the restoring force ``f`` rebuilt from the measured
        orders at the largest amplitude of up to :data:`N_LOOPS` levels.
    orders : list of str
        The measured orders the loops and shares use.
    """

    location: str
    read_at: str
    note: str
    rotation: bool
    stiffness_offset: float
    amplitude: np.ndarray
    omega: np.ndarray
    level_n: np.ndarray
    k_eq: np.ndarray
    c_eq: np.ndarray
    sigma_k: np.ndarray
    sigma_c: np.ndarray
    even_share: np.ndarray
    odd_share: np.ndarray
    seen: np.ndarray
    reading: LawReading | None
    loops: list[dict] = field(default_factory=list)
    orders: list[str] = field(default_factory=list)

    @property
    def units(self) -> dict[str, str]:
        """Units of the amplitude, velocity, force, stiffness and damping."""
        if self.rotation:
            return {"x": "rad", "v": "rad/s", "f": "N m", "k": "N m/rad", "c": "N m s/rad"}
        return {"x": "m", "v": "m/s", "f": "N", "k": "N/m", "c": "N s/m"}

    @property
    def kind(self) -> str:
        return "not_seen" if self.reading is None else self.reading.kind

    @property
    def text(self) -> str:
        """The reading in words (:func:`_words`)."""
        return _words(self)

    def to_json(self) -> dict:
        u = self.units

        def arr(v) -> list:
            return [_finite(x) for x in np.asarray(v, float)]

        return {
            "location": self.location,
            "read_at": self.read_at,
            "note": self.note,
            "kind": self.kind,
            "units": u,
            "stiffness_offset": self.stiffness_offset,
            "text": self.text,
            "reading": None if self.reading is None else self.reading.to_json(),
            "steps": {
                f"amplitude_{_slug(u['x'])}": arr(self.amplitude),
                f"velocity_amplitude_{_slug(u['v'])}": arr(self.amplitude * self.omega),
                "omega_rad_per_s": arr(self.omega),
                "level_n": arr(self.level_n),
                f"k_eq_{_slug(u['k'])}": arr(self.k_eq),
                f"c_eq_{_slug(u['c'])}": arr(self.c_eq),
                f"sigma_k_{_slug(u['k'])}": arr(self.sigma_k),
                f"sigma_c_{_slug(u['c'])}": arr(self.sigma_c),
                "even_share": arr(self.even_share),
                "odd_share": arr(self.odd_share),
                "seen": self.seen.tolist(),
            },
            "orders": self.orders,
            "loops": [
                {
                    "level_n": lp["level_n"],
                    "frequency_hz": lp["frequency_hz"],
                    f"x_{_slug(u['x'])}": lp["x"].tolist(),
                    f"v_{_slug(u['v'])}": lp["v"].tolist(),
                    f"f_{_slug(u['f'])}": lp["f"].tolist(),
                }
                for lp in self.loops
            ],
        }


def _slug(unit: str) -> str:
    return unit.replace(" ", "_").replace("/", "_per_")


def read_missing_force(screen, location: Location) -> ForceReadout:
    """The missing force at ``location`` read from ``screen``'s force estimate (module notes).

    A location of one incidence (a point, a direction, one spring, a joint direction, a pair
    of nodes) is read as it is; a group of springs at the member whose force the sensors see
    most (the group's whole force attributed to it). Reuses the screen's states: no balance
    is solved.

    Raises
    ------
    ValueError
        If the location has no incidence (a linear parameter) or the file has no first order.
    """
    if not location.incidences:
        raise ValueError(
            f"read-out at {location.name!r}: the location has no place in the structure (a "
            "linear parameter); a force can be read at a point, a spring, a joint or a pair"
        )
    orders = [Fraction(o) for o in screen.predictor.orders]
    if Fraction(1) not in orders:
        raise ValueError(
            f"read-out at {location.name!r}: the file records no first order "
            f"(orders {[str(o) for o in orders]})"
        )
    k1 = orders.index(Fraction(1))
    screen._anchor_points()
    fr = screen.frame(location.joint)
    note = ""
    at = location
    if len(location.incidences) > 1:
        at = _member_seen_most(screen, fr, location, k1)
        note = (
            f"the member of {location.name} the sensors see most, the group's force "
            "attributed to it alone"
        )
    B = screen._incidence(fr, at)
    st = screen.states(fr, B, (id(fr), at))
    x, r, Pr, Px = _at_incidence(screen, fr, st, B)
    rows = screen.rows
    omega = 2 * np.pi * screen.data.frequency_hz[rows]
    with np.errstate(divide="ignore", invalid="ignore"):
        k_eq, c_eq = describing_function(x[:, k1], r[:, k1], omega)
        d1 = r[:, k1] / x[:, k1]
        snr_x = np.abs(x[:, k1]) / np.linalg.norm(Px[:, k1], axis=1)
    A = np.abs(x[:, k1])
    seen = np.isfinite(d1) & (np.nan_to_num(snr_x) >= SNR_MIN)
    sigma_d = _ratio_noise(d1, x[:, k1], Pr[:, k1], Px[:, k1], A, seen)
    sigma_k = sigma_d / math.sqrt(2)  # circular: half the variance in each part
    sigma_c = sigma_k / omega
    offset = _stiffness_offset(location)
    k_eq = k_eq + offset
    even, odd, summary = _distortion(orders, x, r, Pr, Px, d1, A, seen)
    reading = None
    if seen.sum() >= 4:
        s = seen
        reading = read_law(
            A[s], omega[s], k_eq[s], c_eq[s], sigma_k[s], sigma_c[s], distortion=summary
        )
    data = screen.data
    level = np.asarray(data.levels_n, float)[np.asarray(data.level_index)[rows]]
    return ForceReadout(
        location.name,
        at.name,
        note,
        at.incidences[0][0].direction in ("rx", "ry", "rz"),
        offset,
        A,
        omega,
        level,
        k_eq,
        c_eq,
        sigma_k,
        sigma_c,
        even,
        odd,
        seen,
        reading,
        _loops(orders, x, r, omega, A, level, offset, seen),
        [str(o) for o in orders],
    )


def _ratio_noise(d1, x1, Pr1, Px1, A, seen, passes: int = 3) -> np.ndarray:
    """Standard errors of the per-step describing functions ``d1 = r1/x1``.

    ``r1 - D x1`` is linear in the data for a given ``D``, its error ``|Pr - D Px|``; taken at
    each step's own ratio it vanishes where the step's force is mostly noise (the ratio of two
    noisy estimates then tends to the structure's dynamic stiffness, where the noise of the
    force and of the displacement cancel), which would weigh the noisiest steps most. It is
    taken at the binned describing function instead (a weighted mean over the steps of
    similar amplitude), recomputed with the errors so found, ``passes`` times."""
    out = np.full(A.size, np.inf)
    if seen.sum() < 4:
        return out
    ok = np.flatnonzero(seen)
    d = np.full(ok.size, complex(np.median(d1[ok].real), np.median(d1[ok].imag)))
    for _ in range(passes):
        s = np.linalg.norm(Pr1[ok] - d[:, None] * Px1[ok], axis=1) / A[ok]
        s = np.maximum(s, 1e-12 * np.abs(d) + 1e-300)
        re = amplitude_bins(A[ok], d1[ok].real, s)
        im = amplitude_bins(A[ok], d1[ok].imag, s)
        la = np.log(A[ok])
        d = np.interp(la, np.log(re.A), re.y) + 1j * np.interp(la, np.log(im.A), im.y)
    out[ok] = np.linalg.norm(Pr1[ok] - d[:, None] * Px1[ok], axis=1) / A[ok]
    return out


def _stiffness_offset(location: Location) -> float:
    if location.joint is None:
        return 0.0
    from analysis.diagnosis.screen import JOINT_ANCHOR

    return JOINT_ANCHOR


def _at_incidence(screen, fr, st, B):
    """Per step and measured order: the incidence's displacement ``x``, the restoring force
    ``r = -g`` there, and their derivatives with respect to the weighted data."""
    x = np.einsum("nkd,d->nk", st.U, B[0])
    Px = np.einsum("nkdc,d->nkc", st.P, B[0])
    if st.grouped:
        # one generalized force distributed like the anchor's displacements (Screen.states)
        shape = np.einsum("nkj,lj->nkl", fr.X0[:, screen._basis.order_k], B)
        shape /= np.maximum(np.linalg.norm(shape, axis=2, keepdims=True), 1e-300)
        g = st.g[:, :, -1] * shape[:, :, 0]
        Pg = st.Pg[:, :, -1, :] * shape[:, :, 0, None]
    else:
        g, Pg = st.g[:, :, -1], st.Pg[:, :, -1, :]
    return x, -g, -Pg, Px


def _member_seen_most(screen, fr, location: Location, k1: int) -> Location:
    """The member of a group whose unit force moves the sensors most at the first order
    (measured order ``k1``), over the noise (summed over the steps), named as the structure's
    own location."""
    C = screen.n_channels
    B = screen._incidence(fr, location)
    W = 1.0 / screen._sigma[screen.rows][:, k1, :]  # (n, C)
    resp = np.einsum("ncd,ld->nlc", fr.R_o[:, k1, :C, 1:], B) * W[:, None, :]
    seen = np.sum(np.abs(resp) ** 2, axis=(0, 2))
    i = int(np.argmax(seen))
    inc = location.incidences[i]
    for loc in default_locations(screen.model, "structure"):
        # a spring may be folded into a place that moves as it (Location.alike)
        for place in (loc, *loc.alike):
            if place.kind == "spring" and place.incidences == (inc,):
                return place
    return Location(f"{location.name} member {i + 1}", (inc,), kind_="spring")


def _distortion(orders: Sequence[Fraction], x, r, Pr, Px, d1, A, seen):
    """Per step, the force's even and odd orders that the first harmonic's describing
    function does not account for, over the first harmonic; and their median over the upper
    half of the amplitudes of the steps seen, with whether they stand above the noise there
    and reach :data:`DISTORTION_SHARE`."""
    n = A.size
    shares = {"even": np.full(n, np.nan), "odd": np.full(n, np.nan)}
    k1 = orders.index(Fraction(1))
    upper = seen & (A >= np.median(A[seen])) if seen.any() else seen
    summary = {}
    for name, parity in (("even", 0), ("odd", 1)):
        idx = [
            i
            for i, o in enumerate(orders)
            if o.denominator == 1 and o.numerator > 1 and o.numerator % 2 == parity
        ]
        if not idx:
            continue
        power = np.zeros(n)
        z = np.zeros(n)
        for i in idx:
            h = float(orders[i])
            d = d1.real + 1j * h * d1.imag  # k_eq + i h omega c_eq
            with np.errstate(invalid="ignore"):
                rest = r[:, i] - d * x[:, i]
                s2 = np.sum(np.abs(Pr[:, i] - d[:, None] * Px[:, i]) ** 2, axis=1)
            power += np.abs(rest) ** 2
            z += np.abs(rest) ** 2 / np.maximum(s2, 1e-300)
        with np.errstate(divide="ignore", invalid="ignore"):
            shares[name] = np.sqrt(power) / np.abs(r[:, k1])
        m = len(idx) * int(upper.sum())
        if m == 0:
            continue
        share = float(np.median(shares[name][upper]))
        # |noise|^2 / sigma^2 is exponential with mean 1: the sum has mean and variance m
        above = bool(z[upper].sum() > m + 3 * math.sqrt(m))
        summary[name] = (share, above and share >= DISTORTION_SHARE)
    return shares["even"], shares["odd"], summary


def _loops(orders, x, r, omega, A, level, offset: float, seen) -> list[dict]:
    """One period of displacement, velocity and restoring force at the largest amplitude seen
    of up to :data:`N_LOOPS` levels (the joint's anchor spring included in a joint's force)."""
    den = math.lcm(*(o.denominator for o in orders))
    theta = np.linspace(0.0, 2 * np.pi * den, LOOP_SAMPLES, endpoint=False)
    ords = np.array([float(o) for o in orders])
    E = np.exp(1j * np.outer(theta, ords))  # (T, K)
    levels = sorted(set(level[seen].tolist()))
    if len(levels) > N_LOOPS:
        pick = np.linspace(0, len(levels) - 1, N_LOOPS).round().astype(int)
        levels = [levels[i] for i in pick]
    out = []
    for lv in levels:
        at = np.flatnonzero((level == lv) & seen)
        i = int(at[np.argmax(A[at])])
        xt = (E @ x[i]).real
        vt = (E @ (1j * ords * omega[i] * x[i])).real
        ft = (E @ r[i]).real + offset * xt
        out.append(
            {
                "level_n": float(lv),
                "frequency_hz": float(omega[i] / (2 * np.pi)),
                "x": xt,
                "v": vt,
                "f": ft,
            }
        )
    return out


# -- in words ----------------------------------------------------------------------------------
def _g(x: float) -> str:
    return f"{x:.3g}"


def _slope_words(fit: AmplitudeFit, of: str) -> str:
    if not fit.changes:
        return f"{of}: no change beyond the noise"
    if not fit.resolved:
        return f"{of}: slope not resolved"
    return f"log-log slope of {of} {fit.p:.2f} +/- {fit.sigma_p:.2f}"


def _what(ro: ForceReadout) -> str:
    return "moment" if ro.rotation else "force"


def _words(ro: ForceReadout) -> str:
    """The reading in words: what the force acts like, how its stiffness and damping change
    with the amplitude, its distortion, and the element to write."""
    where = ro.read_at if not ro.note else f"{ro.read_at} ({ro.note})"
    n_seen = int(ro.seen.sum())
    r = ro.reading
    if r is None:
        return (
            f"At {where} the missing {_what(ro)} stands above its noise at {n_seen} of "
            f"{ro.seen.size} steps: too few to read how it changes with the amplitude."
        )
    u = ro.units
    A = ro.amplitude[ro.seen]
    kb = r.k_bins
    own = "the joint's stiffness" if ro.stiffness_offset else "its stiffness"
    head = (
        f"At {where} the missing {_what(ro)} acts like {r.description} (read at {n_seen} "
        f"of {ro.seen.size} steps, amplitudes {_g(A.min())} to {_g(A.max())} {u['x']})"
    )
    dk = r.stiffness_change
    if dk:
        stiff = (
            f"{own} {'rises' if dk > 0 else 'falls'} from {_g(kb.y[0])} to {_g(kb.y[-1])} "
            f"{u['k']} as the amplitude rises ({_slope_words(r.stiffness, 'k_eq - k_0')}; "
            "cubic: 2)"
        )
    else:
        stiff = f"{own} stays near {_g(_mean(kb))} {u['k']} (no change beyond the noise)"
    parts = [stiff, _damping_words(r, u), _distortion_words(r), "write " + _advice(ro)]
    return head + ": " + "; ".join(parts) + "."


def _mean(b: Bins) -> float:
    w = 1.0 / b.sigma**2
    return float(np.sum(w * b.y) / w.sum())


def _damping_words(r: LawReading, u: dict) -> str:
    c, cb = r.damping, r.c_bins
    form = {
        "velocity": ", a function of the velocity amplitude (a damper)",
        "amplitude": ", a function of the displacement amplitude (friction, hysteresis)",
        "either": "",
    }[r.damping_form]
    slope = f"{_slope_words(c, 'c_eq')}; viscous 0, quadratic 1, Coulomb -1{form}"
    if r.peak is not None:
        i = int(np.argmax(r.h_bins.y))
        energy = ""
        if r.below_peak is not None and r.below_peak.resolved:
            energy = (
                f"; below it the energy per cycle grows as A^{2 + r.below_peak.p:.2f} +/- "
                f"{r.below_peak.sigma_p:.2f} (micro-slip: 2 to 3)"
            )
        return (
            f"its damping is {_g(cb.y[0])} {u['c']} at the smallest amplitudes, its dissipation "
            f"omega c_eq peaking near {_g(r.peak)} {u['x']} ({_g(cb.y[i])} {u['c']}){energy}; "
            f"then it falls to {_g(cb.y[-1])} {u['c']} ({slope}, above the peak)"
        )
    if c.changes:
        return (
            f"its damping goes from {_g(cb.y[0])} to {_g(cb.y[-1])} {u['c']} ({slope}, over "
            "the upper half of the amplitudes)"
        )
    whole = r.damping_whole
    if whole.changes:
        return (
            f"its damping goes from {_g(cb.y[0])} to {_g(cb.y[-1])} {u['c']} over the range "
            f"({_slope_words(whole, 'c_eq')} over the whole range; over the upper half of the "
            f"amplitudes {slope})"
        )
    return f"its damping stays near {_g(_mean(cb))} {u['c']} ({slope})"


def _distortion_words(r: LawReading) -> str:
    out = []
    for name, share, seen, means in (
        ("even", r.even_share, r.even_seen, "asymmetry"),
        ("odd", r.odd_share, r.odd_seen, "a shape that is not a straight line"),
    ):
        if not np.isfinite(share):
            continue
        out.append(
            f"{name} {100 * share:.0f} % of the first"
            + (f" ({means})" if seen else " (not claimed)")
        )
    return "orders above the first: " + (", ".join(out) if out else "none recorded")


def _advice(ro: ForceReadout) -> str:
    """The element to write, with starting values from the binned describing functions at
    the largest amplitudes."""
    r = ro.reading
    assert r is not None
    u = ro.units
    kind = r.kind
    A = float(r.c_bins.A[-1])
    w = float(np.median(ro.omega[ro.seen]))
    c_top = float(r.c_bins.y[-1])
    slip = math.pi / 4 * w * c_top * A  # omega c_eq A = 4 F_s / pi at macro-slip
    if kind == "stick_slip":
        return (
            "an element whose stiffness falls and whose dissipation rises, then falls with "
            "the amplitude: a spring in series with a Coulomb slider (Jenkins), or several in "
            f"parallel (Iwan), beside a spring; stuck about {_g(r.k_bins.y.max())} {u['k']} "
            "(the largest binned stiffness), "
            f"slipping about {_g(r.k_bins.y[-1])} {u['k']}, slip {_what(ro)} about "
            f"{_g(slip)} {u['f']} (pi/4 omega c_eq A at the largest amplitudes)"
        )
    if kind == "coulomb_friction":
        return (
            f"a slider f = -F_s sign(v), F_s about {_g(slip)} {u['f']} (pi/4 omega c_eq A), "
            "in parallel with the stiffness above"
        )
    if kind == "quadratic_damper":
        return f"a damper f = -c2 v|v|, c2 about {_g(3 * math.pi / 8 * c_top / (w * A))}"
    if kind == "cubic_damper":
        return f"a damper f = -c3 v^3, c3 about {_g(4 / 3 * c_top / (w * A) ** 2)}"
    if kind == "amplitude_damping":
        fit = r.damping if r.damping.changes else r.damping_whole
        if float(r.c_bins.y[-1]) < float(r.c_bins.y[0]):
            return (
                "a friction-like law, its damping falling with the amplitude more slowly than "
                "Coulomb friction's A^-1 over this range (a slider whose switch is "
                "regularised, or that sticks, at the smallest amplitudes)"
            )
        return (
            f"a damper whose force grows with the velocity faster than linearly "
            f"(c_eq ~ A^{fit.p:.2g} where resolved; quadratic 1, cubic 2)"
        )
    if kind in ("cubic_hardening", "cubic_softening"):
        k3 = 4 / 3 * r.stiffness_change / A**2
        return f"a spring f = -k3 u^3, k3 about {_g(k3)} {u['f']}/{u['x']}^3"
    if kind in ("hardening", "softening"):
        grows = "grows" if kind == "hardening" else "falls"
        return f"a spring whose stiffness {grows} with the amplitude (see the slope)"
    if kind == "asymmetric_softening":
        return (
            "a law stiffer on one side than on the other (a bilinear spring, a clearance on one "
            "side), which the even orders show"
        )
    if kind == "one_sided_stop":
        return (
            "a one-sided stop (a gap or a contact): a force on one side only, which the even "
            "orders show"
        )
    return "nothing yet: the data do not show how the force changes with the amplitude"
