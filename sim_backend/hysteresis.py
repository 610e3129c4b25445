"""A hysteretic element for the simulator only: the Jenkins element (spring and slider in series).

The analysis library's laws are memoryless (``f(u, v)``). A bolted or clamped joint with
microslip is not: its force depends on where the slider last stuck. The Jenkins element,

    f = -k_t (u - z),   |k_t (u - z)| <= f_s,   z moves only while the slider slips,

(tangential stiffness ``k_t``, slip force ``f_s``) gives a load-dependent stiffness (stuck:
``k_t``; slipping: 0) and a hysteresis loop with the dissipation of Coulomb friction. It exists
so that a truth can hold an effect *outside* the library (``truths/hysteretic_joint.toml``).

Importing this module registers the kind ``"jenkins"`` in the element registry, which the
simulator's model files resolve through; the analysis package never imports it, so the kind
is not part of the library a diagnosis proposes. How the simulator evaluates it:

* the balance (:class:`~sim_backend.rig_model.RigModel`, AFT): ``evaluate`` receives one
  period of samples and marches the slider over the period twice (the second pass starts from
  the state the first ends in, the periodic state of a loop that closes); the derivative is the
  local tangent (``-k_t`` stuck, 0 slipping), so Newton converges linearly near the switches;
* the time engine (:mod:`sim_backend.integrator`): ``evaluate`` receives successive instants;
  the slider state is kept in the element and advanced by each call (return mapping from the
  last state), so a Newton iteration within a step that overshoots into slip leaves a slider
  error of the size of that overshoot.

References
----------
K. L. Johnson, *Contact Mechanics*, Cambridge University Press 1985, sec. 7.2 (microslip).
D. J. Segalman, "A four-parameter Iwan model for lap-type joints", J. Appl. Mech. 72 (2005)
752-760 (Jenkins elements as the building block of joint models).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from analysis.elements.base import ELEMENT_TYPES, ElementEval, NonlinearElement, register

__all__ = ["JenkinsElement"]

#: Fewest samples of an array taken as one period of a periodic motion (the balance's AFT);
#: shorter arrays are successive instants of the time engine.
PERIOD_SAMPLES = 16


@njit(cache=True)
def _march(u: np.ndarray, k: float, fs: float, z0: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Slider positions and stick flags over samples ``u`` (one dimension) from slider ``z0``.

    Compiled: the balance marches the period twice at every evaluation (1024 samples on the
    simulated rig)."""
    z = np.empty_like(u)
    stuck = np.empty(u.shape, np.bool_)
    zc = z0
    dz = fs / k
    for i in range(u.size):
        ui = u[i]
        if ui - zc > dz:
            zc = ui - dz
            stuck[i] = False
        elif ui - zc < -dz:
            zc = ui + dz
            stuck[i] = False
        else:
            stuck[i] = True
        z[i] = zc
    return z, stuck, zc


@njit(cache=True)
def _instant(u: np.ndarray, v: np.ndarray, p: np.ndarray, z: np.ndarray):
    """Force and tangents of sliders ``z`` (advanced in place by the return mapping) at the
    instant ``u``: the time engine's law (``v`` unused)."""
    k, fs = p[0], p[1]
    dz = fs / k
    f = np.empty_like(u)
    df_du = np.empty_like(u)
    for i in range(u.size):
        zi = min(max(z[i], u[i] - dz), u[i] + dz)
        df_du[i] = -k if zi == z[i] else 0.0
        z[i] = zi
        f[i] = -k * (u[i] - zi)
    return f, df_du, np.zeros_like(u)


class JenkinsElement(NonlinearElement):
    """Jenkins element: spring ``k_t`` in series with a Coulomb slider of force ``f_s``.

    Parameters
    ----------
    k_t : float
        Tangential stiffness while stuck [N/m or N m/rad], > 0.
    f_s : float
        Slip force [N or N m], > 0.
    """

    kind = "jenkins"
    param_names = ("k_t", "f_s")
    param_units = ("N/m", "N")
    positive_params = ("k_t", "f_s")
    description = "Jenkins element (spring in series with a Coulomb slider), hysteretic"

    def __init__(self, **values: float) -> None:
        super().__init__(**values)
        self._z = np.zeros(0)  # slider states of the time engine, one per element evaluated

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        k, fs = self._p
        if u.ndim == 1 and u.size >= PERIOD_SAMPLES:
            _, _, z_end = _march(u, k, fs, 0.0)
            z, stuck, _ = _march(u, k, fs, z_end)
            f = -k * (u - z)
            df_du = np.where(stuck, -k, 0.0)
        else:
            flat = np.ascontiguousarray(u, dtype=float).ravel()
            law, p, state = self.compiled_instant_law(flat.size)
            f, df_du, _ = (a.reshape(u.shape) for a in law(flat, flat, p, state))
            z, stuck = state.reshape(u.shape), df_du != 0.0
        dp = None
        if want_params:
            dp = np.stack([np.where(stuck, -(u - z), 0.0), np.where(stuck, 0.0, np.sign(f))])
        return ElementEval(f, df_du, np.zeros_like(u), dp)

    def compiled_instant_law(self, n: int):
        """The time engine's law for ``n`` sliders evaluated together (the integrator's
        :meth:`~sim_backend.integrator.ElementSet.compiled`): the return mapping from each slider's
        last state, which the call advances."""
        if self._z.shape != (n,):
            self._z = np.zeros(n)
        return _instant, self._p, self._z


if ELEMENT_TYPES.get(JenkinsElement.kind) is not JenkinsElement:
    register(JenkinsElement)
