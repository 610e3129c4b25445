"""A locally nonlinear structure set up for multi-harmonic balance.

The balance is written on the nonlinear DOFs only (receptance form): for every harmonic ``k``
of the base frequency,

    Q_n,k = H_nn(k w) F_nl,k(Q_n) + H_nf(k w) F_ext,k

and every other DOF is recovered afterwards from the converged nonlinear forces,

    Q_o,k = H_on(k w) F_nl,k + H_of(k w) F_ext,k.

References
----------
J. V. Ferreira, D. J. Ewins, "Multi-harmonic nonlinear receptance coupling approach",
Proc. IMAC XV, 1997. T. Abrahamsson et al. / Y. Chen et al. (the reference paper) use this form.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from analysis.elements.base import NonlinearElement
from analysis.linear.receptance import LinearModel, frequency_derivative
from analysis.mhb import kernels
from analysis.mhb.harmonics import HarmonicBasis, base_denominator, order_indices

__all__ = ["Attachment", "HarmonicProblem", "LINEAR_CACHE_SIZE", "real_operator"]

#: frequencies whose receptance blocks a problem keeps (:meth:`HarmonicProblem.receptances`):
#: a stepped test's every level at the same frequencies, a few hundred steps
LINEAR_CACHE_SIZE = 1024


def real_operator(Hc: np.ndarray) -> np.ndarray:
    """Real coefficient operator of complex receptances.

    Parameters
    ----------
    Hc : ndarray, shape (H+1, r, c), complex
        Receptance at harmonics ``0..H`` (harmonic 0 must be real).

    Returns
    -------
    ndarray, shape ((2H+1) r, (2H+1) c)
        ``G`` such that coefficients of ``Re{Hc X}`` are ``G @ x`` (coefficient-major order).
    """
    Hn, r, c = Hc.shape
    H = Hn - 1
    G = np.zeros((2 * H + 1, r, 2 * H + 1, c))
    G[0, :, 0, :] = Hc[0].real
    ia = np.arange(1, 2 * H, 2)
    ib = ia + 1
    Hr, Hi = Hc[1:].real, Hc[1:].imag
    G[ia, :, ia, :] = Hr
    G[ia, :, ib, :] = Hi
    G[ib, :, ia, :] = -Hi
    G[ib, :, ib, :] = Hr
    return G.reshape((2 * H + 1) * r, (2 * H + 1) * c)


class _Receptances(dict[str | tuple[str, str, str], np.ndarray]):
    """One frequency's receptance blocks, each computed when first asked for (a continuation
    step needs ``G`` and ``nf`` at every trial frequency, the outputs' blocks only at the
    points it keeps); ``("d", block, parameter)`` is a block's derivative with respect to a
    parameter of the linear structure."""

    def __init__(self, blocks: dict, w: np.ndarray) -> None:
        w.setflags(write=False)
        super().__init__()
        self["w"] = w
        self._blocks = blocks

    def __missing__(self, name: str | tuple[str, str, str]) -> np.ndarray:
        w = self["w"]
        if name == "G":
            Hnn = np.array(self["nn"])
            Hnn[0] = Hnn[0].real
            value = real_operator(Hnn)
        elif isinstance(name, tuple):
            _, block, param = name
            value = self._blocks[block].derivative(w, param)
        else:
            value = self._blocks[name](w)
        value.setflags(write=False)
        self[name] = value
        return value


@dataclass(frozen=True)
class Attachment:
    """A nonlinear element placed between two structural DOFs (or a DOF and ground).

    Parameters
    ----------
    element : NonlinearElement
    dof_a : int
        Structural DOF index the element force acts on.
    dof_b : int or None
        Second DOF (reaction), ``None`` for ground.
    name : str
    param_map : dict
        Model parameter name -> element parameter name, for sensitivities with respect to
        model parameters (an element parameter not in the map has no model parameter).
    """

    element: NonlinearElement
    dof_a: int
    dof_b: int | None = None
    name: str = ""
    param_map: dict[str, str] = field(default_factory=dict)


@dataclass
class HarmonicProblem:
    """Linear structure + nonlinear attachments + excitation DOFs + outputs + harmonic basis.

    Parameters
    ----------
    linear : LinearModel
        Provides receptance blocks between DOF sets.
    attachments : sequence of Attachment
    force_dofs : list of int
        DOFs where external forces act (one per column of the force phasors).
    output_dofs : list of int
        DOFs whose harmonics are recovered (sensors).
    orders : sequence of Fraction
        Orders of the excitation (1, 2, 3 for the reference test; 1/2 for a sub-harmonic).
    n_harmonics : int
        Harmonics of the base frequency kept in the balance.
    n_time : int
        AFT samples per base period.
    """

    linear: LinearModel
    attachments: list[Attachment]
    force_dofs: list[int]
    output_dofs: list[int]
    orders: tuple[Fraction, ...] = (Fraction(1), Fraction(2), Fraction(3))
    n_harmonics: int = 9
    n_time: int = 256

    def __post_init__(self) -> None:
        self.orders = tuple(Fraction(o) for o in self.orders)
        den = base_denominator(self.orders)
        self.basis = HarmonicBasis(self.n_harmonics, self.n_time, den)
        self.order_k = order_indices(self.orders, den)
        if self.order_k.max() > self.n_harmonics:
            raise ValueError(
                f"HarmonicProblem.n_harmonics={self.n_harmonics} is below the highest order "
                f"({max(self.orders)} = harmonic {self.order_k.max()} of the base)"
            )
        nl: list[int] = []
        for att in self.attachments:
            for d in (att.dof_a, att.dof_b):
                if d is not None and d not in nl:
                    nl.append(d)
        self.nl_dofs = nl
        n = len(nl)
        self.n_nl = n
        # incidence: relative displacement of element e = L[e] @ q_nl
        L = np.zeros((len(self.attachments), n))
        for e, att in enumerate(self.attachments):
            L[e, nl.index(att.dof_a)] = 1.0
            if att.dof_b is not None:
                L[e, nl.index(att.dof_b)] = -1.0
        self.L = L
        # L[e, i] L[e, j] of each element, shape (n_elements, n * n): the Jacobian's assembly
        self.incidence_products = np.einsum("ei,ej->eij", L, L).reshape(len(L), n * n)
        self.blocks = {
            "nn": self.linear.block(nl, nl) if n else None,
            "nf": self.linear.block(nl, self.force_dofs) if n else None,
            "on": self.linear.block(self.output_dofs, nl) if n else None,
            "of": self.linear.block(self.output_dofs, self.force_dofs),
        }
        self._receptances: OrderedDict[float, _Receptances] = OrderedDict()
        b = self.basis
        self.kernel_basis = (b.EdE, b.tau, b.k, b.P, b.E, b.dE, b.jump_weights)
        self._element_arrays: kernels.ElementArrays | None | str = "not made"

    # ------------------------------------------------------------------------------------
    @property
    def denominator(self) -> int:
        return self.basis.denominator

    def harmonic_omegas(self, omega: float) -> np.ndarray:
        """Angular frequencies of harmonics ``0..H`` of the base, shape (H+1,), rad/s."""
        return np.arange(self.n_harmonics + 1) * (omega / self.denominator)

    def receptances(self, omega: float) -> _Receptances:
        """The receptance blocks at the harmonics of ``omega`` (read-only arrays, each computed
        when first asked for): ``w`` the harmonics' angular frequencies, ``nf``, ``on``, ``of``
        the blocks (H+1, rows, cols), ``G`` the real operator of ``nn`` (harmonic 0 real) on
        the balance's coefficients.

        They depend on the frequency alone, and a stepped test solves every level at the same
        frequencies: each frequency's are kept (the last :data:`LINEAR_CACHE_SIZE`). Problems
        made by :meth:`with_elements` share them, as they share the linear structure.
        """
        key = float(omega)
        out = self._receptances.get(key)
        if out is not None:
            self._receptances.move_to_end(key)
            return out
        out = _Receptances(self.blocks, self.harmonic_omegas(key))
        self._receptances[key] = out
        if len(self._receptances) > LINEAR_CACHE_SIZE:
            self._receptances.popitem(last=False)
        return out

    def prefetch(self, omegas: np.ndarray, params: Sequence[str] = ()) -> None:
        """Make :meth:`receptances` hold the blocks at the harmonics of every frequency in
        ``omegas`` [rad/s], and their derivatives with respect to those of ``params`` that are
        the linear structure's, each evaluated once over all the frequencies: a new model's
        sweep needs them at each of its steps, and one evaluation over a sweep's harmonics
        costs little more than one over a step's (the same values: a block's entries at a
        frequency do not depend on the others asked for)."""
        lin = set(getattr(self.linear, "param_names", ()))
        names: list[tuple[str, str | None]] = [
            (name, None) for name, block in self.blocks.items() if block is not None
        ]
        names += [(name, p) for name, _ in names for p in dict.fromkeys(params) if p in lin]
        freqs = list(dict.fromkeys(float(w) for w in np.atleast_1d(omegas)))
        recs = [self.receptances(w) for w in freqs[-LINEAR_CACHE_SIZE:]]
        for name, param in names:
            key = name if param is None else ("d", name, param)
            todo = [r for r in recs if key not in r]
            if not todo:
                continue
            block = self.blocks[name]
            W = np.concatenate([r["w"] for r in todo])
            v = block(W) if param is None else block.derivative(W, param)
            v = v.reshape(len(todo), self.n_harmonics + 1, *v.shape[1:])
            v.setflags(write=False)
            for i, r in enumerate(todo):
                r[key] = v[i]

    def element_arrays(self) -> kernels.ElementArrays | None:
        """The elements as the compiled kernels take them (:mod:`analysis.mhb.kernels`), or
        None when a law is not one of the library's; made at the first call."""
        if isinstance(self._element_arrays, str):
            self._element_arrays = kernels.element_arrays(self)
        return self._element_arrays

    def compiled_forces(
        self, X: np.ndarray, omega_b: float, jacobian: bool
    ) -> tuple[np.ndarray, np.ndarray | None] | None:
        """:func:`analysis.mhb.aft.nonlinear_forces` in one compiled call, or None when a law
        is not one of the library's."""
        arrays = self.element_arrays()
        if arrays is None:
            return None
        F, dF = kernels.problem_forces(
            np.ascontiguousarray(X, dtype=float),
            float(omega_b),
            arrays.codes,
            arrays.params,
            arrays.n_params,
            arrays.thresholds,
            arrays.L,
            self.kernel_basis,
            jacobian,
        )
        return F, dF if jacobian else None

    def receptance_rates(self, omega: float) -> dict[str, np.ndarray]:
        """Derivatives with respect to the base's frequency ``omega`` of what
        :meth:`receptances` gives: ``G`` (the real operator of ``nn``) and ``nf``, each
        harmonic's ``k / denominator dH/dw`` at ``w = k omega / denominator``."""
        w = self.harmonic_omegas(omega)
        rate = (np.arange(self.n_harmonics + 1) / self.denominator)[:, None, None]
        dnn = frequency_derivative(self.blocks["nn"], w) * rate
        return {"G": real_operator(dnn), "nf": frequency_derivative(self.blocks["nf"], w) * rate}

    def force_harmonics(self, force: np.ndarray) -> np.ndarray:
        """Spread force phasors per order, shape (n_orders, n_f), onto harmonics (H+1, n_f)."""
        force = np.asarray(force, dtype=complex)
        if force.ndim == 1:
            force = force[:, None]
        if force.shape != (len(self.orders), len(self.force_dofs)):
            raise ValueError(
                f"force phasors: expected shape (n_orders={len(self.orders)}, "
                f"n_force_dofs={len(self.force_dofs)}), got {force.shape}"
            )
        Fk = np.zeros((self.n_harmonics + 1, len(self.force_dofs)), dtype=complex)
        Fk[self.order_k] = force
        return Fk

    def with_elements(self, elements: list[NonlinearElement]) -> HarmonicProblem:
        """Same problem with the attachments' elements replaced (same placement)."""
        atts = [
            Attachment(el, a.dof_a, a.dof_b, a.name, a.param_map)
            for el, a in zip(elements, self.attachments, strict=True)
        ]
        new = object.__new__(HarmonicProblem)
        new.__dict__.update(self.__dict__)
        new.attachments = atts
        new._element_arrays = "not made"
        return new
