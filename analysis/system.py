"""From a model file to a balance problem: the glue between the FE model and the MHB solver.

>>> from analysis.model import load_model
>>> from analysis.system import build_problem
>>> pb = build_problem(load_model(), drive_point=3, output_points=(3, 6, 7))
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

from analysis.linear.receptance import DirectLinearModel, ModalLinearModel
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.model import Assembly, DofRef, Model

__all__ = [
    "DEFAULT_HARMONICS",
    "DEFAULT_TIME_SAMPLES",
    "attachments",
    "build_linear",
    "build_problem",
    "build_problem_dofs",
]

#: Harmonics and AFT samples validated on the reference rig against time integration
#: (``tests/analysis/mhb/test_rig_validation.py``; convergence in H in docs/mhb.md).
DEFAULT_HARMONICS = 9
DEFAULT_TIME_SAMPLES = 128


def build_linear(model: Model, *, f_max_hz: float = 2000.0, damping_modes: Sequence[int] = ()):
    """The linear model (modal with residual flexibility, or direct if C is given or built
    from the model file's Rayleigh coefficients or damping matrix).

    Parameters
    ----------
    model : Model
    f_max_hz : float
        Highest retained mode [Hz]; the rest enters as residual flexibility.
    damping_modes : sequence of int
        Modes (1-based) whose damping ratios are parameters too (``zeta_4``; modal damping
        only).
    """
    asm = model.assemble()
    damping = None if asm.C is not None else model.damping_matrices()
    if damping_modes and (asm.C is not None or damping is not None):
        raise ValueError(
            f"{model.source}: modal damping ratios {list(damping_modes)} as parameters need "
            "modal damping; this model has a damping matrix"
        )
    if asm.C is not None:
        return DirectLinearModel(asm.M, asm.C, asm.K, dM=asm.dM, dK=asm.dK)
    if damping is not None:  # Rayleigh or an explicit C: no modal damping ratios to apply
        C, dC = damping
        return DirectLinearModel(asm.M, C, asm.K, dM=asm.dM, dC=dC, dK=asm.dK)
    return ModalLinearModel(
        asm.M,
        asm.K,
        dict(model.damping.per_mode),
        default_zeta=model.damping.default_zeta,
        f_max_hz=f_max_hz,
        dM=asm.dM,
        dK=asm.dK,
        damping_modes=damping_modes,
    )


def _dof(asm: Assembly, ref: DofRef) -> int:
    if ref.node is not None and ref.direction is not None:
        return asm.dof_index(ref.node, ref.direction)
    return asm.point_dof(ref.point, ref.direction)


def build_problem(
    model: Model,
    *,
    drive_point: int = 3,
    output_points: Sequence[int] = (3, 6, 7),
    orders: Sequence[Fraction | int] = (1, 2, 3),
    n_harmonics: int = DEFAULT_HARMONICS,
    n_time: int = DEFAULT_TIME_SAMPLES,
    f_max_hz: float = 2000.0,
    linear=None,
) -> HarmonicProblem:
    """Balance problem of a model driven at one measurement point.

    Parameters
    ----------
    model : Model
    drive_point : int
        Measurement point of the shaker (force in the point's direction).
    output_points : sequence of int
        Points whose response is recovered (each in its own direction).
    orders : sequence of Fraction or int
        Excitation orders.
    n_harmonics, n_time : int
        Harmonics of the base frequency and AFT samples.
    f_max_hz : float
        Highest retained mode of the linear part.
    linear : LinearModel, optional
        A prebuilt linear model of ``model`` (saves the modal analysis when only nonlinear
        parameters change).

    Returns
    -------
    HarmonicProblem
        ``attachments[i].param_map`` names the model parameters of each element, so
        sensitivities are with respect to model parameters.
    """
    asm = model.assemble()
    return build_problem_dofs(
        model,
        [asm.point_dof(drive_point)],
        [asm.point_dof(p) for p in output_points],
        orders=orders,
        n_harmonics=n_harmonics,
        n_time=n_time,
        f_max_hz=f_max_hz,
        linear=linear,
    )


def attachments(model: Model) -> list[Attachment]:
    """The model's nonlinear elements placed on their structural DOFs."""
    asm = model.assemble()
    atts = []
    for spec, element in model.build_elements():
        pmap = {ref: name for name, ref in spec.params.items() if isinstance(ref, str)}
        atts.append(
            Attachment(
                element,
                _dof(asm, spec.at),
                None if spec.to is None else _dof(asm, spec.to),
                spec.name,
                pmap,
            )
        )
    return atts


def build_problem_dofs(
    model: Model,
    force_dofs: Sequence[int],
    output_dofs: Sequence[int],
    *,
    orders: Sequence[Fraction | int] = (1, 2, 3),
    n_harmonics: int = DEFAULT_HARMONICS,
    n_time: int = DEFAULT_TIME_SAMPLES,
    f_max_hz: float = 2000.0,
    linear=None,
) -> HarmonicProblem:
    """Balance problem with forces and outputs at structural DOF indices of ``model``."""
    lin = linear if linear is not None else build_linear(model, f_max_hz=f_max_hz)
    return HarmonicProblem(
        lin,
        attachments(model),
        list(force_dofs),
        list(output_dofs),
        orders=tuple(Fraction(o) for o in orders),
        n_harmonics=n_harmonics,
        n_time=n_time,
    )
