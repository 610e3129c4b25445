"""Rayleigh damping and an explicit damping matrix in model files."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from analysis.linear.receptance import DirectLinearModel, ModalLinearModel
from analysis.model import Model, ModelFileError, load_model
from analysis.system import build_linear

from .test_model_file import SIMPLE


def _with_damping(text: str) -> str:
    return SIMPLE + "[damping]\n" + text


def test_rayleigh_damping_gives_c_equal_alpha_m_plus_beta_k():
    model = Model.from_toml_text(_with_damping("rayleigh = { alpha = 0.5, beta = 2e-5 }\n"))
    asm = model.assemble()
    C, dC = model.damping_matrices()
    np.testing.assert_array_equal(C, 0.5 * asm.M + 2e-5 * asm.K)
    np.testing.assert_array_equal(dC["E"], 0.5 * asm.dM["E"] + 2e-5 * asm.dK["E"])
    lin = build_linear(model)
    assert isinstance(lin, DirectLinearModel)
    # the receptance is the direct inverse of the dynamic stiffness (exact to round-off)
    w = np.array([3.0, 120.0])
    Z = asm.K - w[:, None, None] ** 2 * asm.M + 1j * w[:, None, None] * C
    np.testing.assert_allclose(
        lin.full(w) @ Z, np.broadcast_to(np.eye(asm.n_dofs), Z.shape), atol=1e-9
    )
    # mass-normalised modes diagonalise C to alpha + beta w_r^2
    # (a damping ratio of alpha / (2 w_r) + beta w_r / 2)
    w2, phi = scipy.linalg.eigh(asm.K, asm.M)
    Cm = phi.T @ C @ phi
    np.testing.assert_allclose(np.diag(Cm), 0.5 + 2e-5 * w2, rtol=1e-9)
    assert np.abs(Cm - np.diag(np.diag(Cm))).max() < 1e-9 * np.abs(Cm).max()


def test_rayleigh_round_trips_through_the_file(tmp_path):
    model = Model.from_toml_text(_with_damping("rayleigh = { alpha = 0.5, beta = 2e-5 }\n"))
    again = Model.from_toml_text(model.to_toml())
    assert again.damping == model.damping and again.damping.rayleigh == (0.5, 2e-5)


def test_explicit_matrix_inline_and_from_a_file(tmp_path):
    n = Model.from_toml_text(SIMPLE).assemble().n_dofs
    C = np.diag(np.linspace(1.0, 2.0, n))
    rows = "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in r) + "]" for r in C) + "]"
    inline = Model.from_toml_text(_with_damping(f"matrix = {rows}\n"))
    np.testing.assert_array_equal(inline.damping_matrices()[0], C)
    np.save(tmp_path / "C.npy", C)
    (tmp_path / "m.toml").write_text(_with_damping('matrix = "C.npy"\n'))
    from_file = load_model(tmp_path / "m.toml")
    np.testing.assert_array_equal(from_file.damping_matrices()[0], C)
    assert isinstance(build_linear(from_file), DirectLinearModel)


def test_modal_damping_is_unchanged():
    model = load_model()
    assert model.damping.modal and model.damping_matrices() is None
    assert isinstance(build_linear(model), ModalLinearModel)


ERRORS = {
    "negative beta": (
        "rayleigh = { alpha = 0.0, beta = -1e-5 }",
        "damping.rayleigh.beta: must be >= 0",
    ),
    "unknown rayleigh key": ("rayleigh = { a = 1.0 }", "damping.rayleigh.a: unknown key"),
    "both forms": (
        "rayleigh = { alpha = 1.0 }\nmatrix = [[1.0]]",
        "damping.rayleigh: give either rayleigh or matrix",
    ),
    "modal and rayleigh": (
        "default_zeta = 0.02\nrayleigh = { alpha = 1.0 }",
        "damping.default_zeta: modal damping ratios and damping.rayleigh exclude each other",
    ),
    "wrong size": ("matrix = [[1.0, 0.0], [0.0, 1.0]]", "damping.matrix: expected 12 x 12"),
    "not square": ("matrix = [[1.0, 0.0], [1.0]]", "damping.matrix: expected a square array"),
    "bad entry": ('matrix = [[1.0, "x"]]', "damping.matrix[0][1]: expected a number"),
    "bad file": ('matrix = "C.txt"', "damping.matrix: a .npy or .mtx file"),
    "missing file": ('matrix = "nowhere.npy"', "damping.matrix: "),
}


@pytest.mark.parametrize(("text", "expected"), ERRORS.values(), ids=ERRORS.keys())
def test_damping_errors_name_the_file_and_key_path(tmp_path, text, expected):
    path = tmp_path / "bad.toml"
    path.write_text(_with_damping(text + "\n"))
    with pytest.raises(ModelFileError) as info:
        load_model(path)
    assert str(path) in str(info.value) and expected in str(info.value)
