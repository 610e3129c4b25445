"""Export and import of linear matrices, and models built on an imported linear part."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg as sla

from analysis.matrix_io import LinearPart, export_linear, import_linear, read_dof_map
from analysis.model import Model, ModelFileError, load_model

FORMATS = ("npz", "mat", "mtx")


@pytest.fixture(scope="module")
def rig():
    return load_model()


def small_part(with_damping: bool = True) -> LinearPart:
    rng = np.random.default_rng(7)
    a = rng.normal(size=(5, 5))
    M = a @ a.T + 5 * np.eye(5)
    K = np.diag([4.0, 3.0, 2.0, 1.0, 0.5]) * 1e6
    K[0, 1] = K[1, 0] = -1.0e5 / 3  # a value that needs all 17 digits
    C = 1e-4 * K if with_damping else None
    dofs = (("n1", "x"), ("n1", "y"), ("n1", "rz"), ("2/a", "z"), ("n3", "ry"))
    return LinearPart(M=M, K=K, C=C, dofs=dofs, node_xy={"n1": (0.1, -0.2)})


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_with_damping(tmp_path, fmt):
    part = small_part()
    written = export_linear(part, tmp_path / f"part.{fmt}")
    assert all(p.exists() for p in written)
    back = import_linear(tmp_path / f"part.{fmt}")
    for name in ("M", "K", "C"):
        # Binary formats are exact; MatrixMarket is written with 17 significant digits.
        np.testing.assert_allclose(getattr(back, name), getattr(part, name), rtol=1e-15, atol=0)
    assert back.dofs == part.dofs
    assert back.node_xy == part.node_xy


@pytest.mark.parametrize("fmt", FORMATS)
def test_rig_round_trip_without_damping(tmp_path, rig, fmt):
    asm = rig.assemble()
    export_linear(rig, tmp_path / f"rig.{fmt}")
    back = import_linear(tmp_path / f"rig.{fmt}")
    assert back.C is None
    assert back.dofs == asm.dofs
    np.testing.assert_allclose(back.K, asm.K, rtol=1e-15, atol=0)
    np.testing.assert_allclose(back.M, asm.M, rtol=1e-15, atol=0)
    assert back.node_xy["tip"] == asm.node_xy["tip"]


def linear_part_model_text(fmt: str) -> str:
    source = {"npz": 'file = "rig.npz"', "mat": 'file = "rig.mat"'}.get(
        fmt, 'files = { M = "rig.M.mtx", K = "rig.K.mtx" }\ndof_map = "rig.dofs.json"'
    )
    return f"""
title = "rig, imported"
[linear_part]
format = "{fmt}"
{source}
[points.3]
node = "p3"
direction = "y"
[points.7]
node = "tip"
direction = "y"
[parameters.k_c]
value = 1e6
[parameters.gap]
value = 1e-3
[[nonlinear]]
name = "bump_stop"
kind = "hertz_contact"
at = {{ point = 7 }}
params = {{ k_c = "k_c", gap = "gap", v = 10.0 }}
"""


@pytest.mark.parametrize("fmt", FORMATS)
def test_model_on_exported_rig_reproduces_eigenfrequencies(tmp_path, rig, fmt):
    export_linear(rig, tmp_path / f"rig.{fmt}")
    path = tmp_path / "imported.toml"
    path.write_text(linear_part_model_text(fmt))
    imported = load_model(path)
    ref, asm = rig.assemble(), imported.assemble()
    lam_ref = sla.eigh(ref.K, ref.M, eigvals_only=True)
    lam = sla.eigh(asm.K, asm.M, eigvals_only=True)
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-9, atol=1e-9 * lam_ref[-1])
    assert asm.point_dof(7) == ref.point_dof(7)
    assert imported.points[7].xy == (0.633, 0.0)
    assert imported.build_elements()[0][1].params == {"k_c": 1e6, "gap": 1e-3, "v": 10.0}
    assert asm.mass_report()["total"] == pytest.approx(ref.mass_report()["total"], rel=1e-12)
    # Round trip of the model file itself, and sensor masses on an imported part.
    heavier = imported.add_masses({3: 0.02})
    saved = heavier.save(tmp_path / "again.toml")
    assert load_model(saved) == heavier
    added = heavier.assemble().mass_report()["total"] - asm.mass_report()["total"]
    assert added == pytest.approx(0.02, rel=1e-9)


def test_inline_dof_map_and_csv(tmp_path):
    part = small_part(with_damping=False)
    export_linear(part, tmp_path / "p.mtx")
    csv_path = tmp_path / "p.dofs.csv"
    csv_path.write_text("node,direction\n" + "".join(f"{n},{d}\n" for n, d in part.dofs))
    dofs, _ = read_dof_map(csv_path)
    assert dofs == part.dofs
    files = {"M": tmp_path / "p.M.mtx", "K": tmp_path / "p.K.mtx", "dof_map": csv_path}
    assert import_linear(files).dofs == part.dofs
    labels = json.dumps([f"{n}/{d}" for n, d in part.dofs])
    text = f"""
[linear_part]
format = "mtx"
files = {{ M = "{tmp_path / "p.M.mtx"}", K = "{tmp_path / "p.K.mtx"}" }}
dof_map = {labels}
[points.1]
node = "2/a"
direction = "z"
"""
    model = Model.from_toml_text(text)
    assert model.assemble().point_dof(1) == 3
    assert Model.from_toml_text(model.to_toml()) == model


def test_import_errors(tmp_path):
    part = small_part()
    with pytest.raises(ValueError, match="K: shape"):
        LinearPart(M=part.M, K=part.K[:4, :4], C=None, dofs=part.dofs)
    with pytest.raises(ValueError, match="not symmetric"):
        LinearPart(M=part.M, K=part.K + np.triu(np.ones((5, 5)), 1), C=None, dofs=part.dofs)
    export_linear(part, tmp_path / "p.mtx")
    (tmp_path / "p.dofs.json").write_text(json.dumps(["n1-x"] * 5))
    with pytest.raises(ValueError, match="bad DOF label 'n1-x'"):
        import_linear(tmp_path / "p.mtx")
    with pytest.raises(ValueError, match="unknown matrix format 'txt'"):
        export_linear(part, tmp_path / "p.txt")
    text = '[linear_part]\nformat = "npz"\nfile = "missing.npz"\n'
    with pytest.raises(ModelFileError, match="linear_part: .*missing.npz"):
        Model.from_toml_text(text, str(tmp_path / "m.toml"))
