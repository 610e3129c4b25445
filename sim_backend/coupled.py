"""The structure coupled to the shaker, as receptance blocks with the voltage as an input.

Closing the shaker's rank-1 loop (``F_st = T V - z x_d`` at drive DOF ``d``, see
:mod:`sim_backend.shaker`) on the structure's receptance ``H`` gives, per frequency
(Sherman-Morrison, ``D = 1 + z H_dd``)::

    x   = (H - z H_:d H_d: / D) f  +  H_:d T / D  V
    F_st = -z H_d: / D  f          +  T / D  V
    I    = -Bl i w k_st H_d: / (D Z_e Z_a) f
           + (1 / Z_e - Bl i w (Bl / Z_e + k_st H_dd T / D) / (Z_e Z_a)) V

where ``f`` are forces on the structure (the nonlinear elements' forces), ``V`` the amplifier's
open-circuit voltage, ``F_st`` the stinger force (what the impedance head measures) and ``I``
the coil current. :class:`CoupledLinearModel` offers this map through the ``block(rows, cols)``
interface of :mod:`analysis.linear.receptance` with pseudo-indices past the structural DOFs:
:attr:`CoupledLinearModel.voltage` (an input column), :attr:`CoupledLinearModel.force` and
:attr:`CoupledLinearModel.current` (output rows). A ``HarmonicProblem`` on it, with the
voltage pseudo-index as its force DOF, balances the coupled nonlinear system directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_backend.shaker import ShakerConstants, shaker_terms

__all__ = ["CoupledLinearModel"]


@dataclass
class _CoupledBlock:
    """Receptance block of the coupled model (see the module notes)."""

    model: CoupledLinearModel
    rows: list[int]
    cols: list[int]

    def __post_init__(self) -> None:
        n = self.model.n_structure
        d = self.model.drive_dof
        self._rs = [r for r in self.rows if r < n]
        self._cs = [c for c in self.cols if c < n]
        lin = self.model.structure
        self._rc = lin.block(self._rs, self._cs) if self._rs and self._cs else None
        self._rd = lin.block(self._rs, [d]) if self._rs else None
        self._dc = lin.block([d], self._cs) if self._cs else None
        self._dd = lin.block([d], [d])

    @property
    def shape(self) -> tuple[int, int]:
        return (len(self.rows), len(self.cols))

    def __call__(self, omega: np.ndarray) -> np.ndarray:
        """Coupled receptance, shape (n_omega, n_rows, n_cols) (m/N, m/V, N/N, N/V, A/N, A/V)."""
        m = self.model
        w = np.atleast_1d(np.asarray(omega, dtype=float))
        terms = shaker_terms(m.shaker, w, m.output_resistance_ohm)
        T, z, Ze, Za = terms.T, terms.z, terms.Ze, terms.Za
        Bl, kst = m.shaker.force_constant_n_per_a, m.shaker.stinger_stiffness_n_per_m
        Hdd = self._dd(w)[:, 0, 0]
        D = 1.0 + z * Hdd
        nw = w.size
        Hrd = self._rd(w)[:, :, 0] if self._rd is not None else np.zeros((nw, 0))
        Hdc = self._dc(w)[:, 0, :] if self._dc is not None else np.zeros((nw, 0))
        n = m.n_structure
        # per structural column c and per volt: drive-point displacement and outputs
        xd_c, xd_v = Hdc / D[:, None], Hdd * T / D
        current_c = -(Bl * 1j * w * kst / (Ze * Za))[:, None] * xd_c
        current_v = 1.0 / Ze - Bl * 1j * w * (Bl / Ze + kst * xd_v) / (Ze * Za)
        struct_rows: dict[int, int] = {r: i for i, r in enumerate(self._rs)}
        struct_cols: dict[int, int] = {c: j for j, c in enumerate(self._cs)}
        Hrc = None
        if self._rc is not None:
            Hrc = self._rc(w) - (z / D)[:, None, None] * Hrd[:, :, None] * Hdc[:, None, :]
        out = np.zeros((nw, len(self.rows), len(self.cols)), dtype=complex)
        for i, r in enumerate(self.rows):
            for j, c in enumerate(self.cols):
                volt = c == m.voltage
                if c >= n and not volt:
                    raise ValueError(f"coupled block: column {c} is not an input")
                if r < n:
                    ri = struct_rows[r]
                    out[:, i, j] = Hrd[:, ri] * T / D if volt else Hrc[:, ri, struct_cols[c]]
                elif r == m.force:
                    out[:, i, j] = T / D if volt else -z * xd_c[:, struct_cols[c]]
                elif r == m.current:
                    out[:, i, j] = current_v if volt else current_c[:, struct_cols[c]]
                else:
                    raise ValueError(f"coupled block: row {r} is not an output")
        return out

    def derivative(self, omega: np.ndarray, param: str) -> np.ndarray:
        raise ValueError(f"the coupled rig model has no parameter {param!r}")


class CoupledLinearModel:
    """Structure receptance coupled to a voltage-driven shaker on a stinger.

    Parameters
    ----------
    structure : LinearModel
        Receptance model of the structure (e.g. ``analysis.system.build_linear``).
    drive_dof : int
        Structural DOF the stinger pushes on.
    shaker : ShakerConstants
    output_resistance_ohm : float
        Amplifier source resistance in series with the coil [ohm].

    Attributes
    ----------
    voltage, force, current : int
        Pseudo-indices: the amplifier's open-circuit voltage (input column), the stinger force
        and the coil current (output rows).
    n_dof : int
        Structural DOFs plus the three pseudo-indices.
    """

    param_names: tuple[str, ...] = ()

    def __init__(
        self,
        structure,
        drive_dof: int,
        shaker: ShakerConstants,
        output_resistance_ohm: float = 0.0,
    ) -> None:
        self.structure = structure
        self.n_structure = int(structure.n_dof)
        if not 0 <= drive_dof < self.n_structure:
            raise ValueError(f"drive_dof: {drive_dof} is not a structural DOF")
        self.drive_dof = int(drive_dof)
        self.shaker = shaker
        self.output_resistance_ohm = float(output_resistance_ohm)
        n = self.n_structure
        self.voltage, self.force, self.current = n, n + 1, n + 2
        self.n_dof = n + 3

    def block(self, rows: list[int], cols: list[int]) -> _CoupledBlock:
        """Block between output rows (structural DOFs, :attr:`force`, :attr:`current`) and
        input columns (structural DOFs, :attr:`voltage`)."""
        return _CoupledBlock(self, list(rows), list(cols))
