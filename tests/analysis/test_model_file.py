"""Model file: parsing, errors with key paths, round trip and the Model's copy methods."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from analysis.elements.base import ELEMENT_TYPES, ElementEval, NonlinearElement, register
from analysis.model import (
    DampingSpec,
    DofRef,
    Model,
    ModelFileError,
    NonlinearSpec,
    Parameter,
    ParameterBoundsWarning,
    load_model,
)
from analysis.model_file import to_document
from analysis.settings import build, dotted, dump


class _TestSpring(NonlinearElement):
    """Linear spring f = -k u, registered under a kind used only by these tests."""

    kind = "model_file_test_spring"
    param_names = ("k",)
    param_units = ("N/m",)

    def _evaluate(self, u, v, want_params):
        k = self._p[0]
        dp = -u[None] if want_params else None
        return ElementEval(f=-k * u, df_du=np.full_like(u, -k), df_dv=np.zeros_like(u), df_dp=dp)


@pytest.fixture
def test_kind():
    """Register the test kind for one test only, leaving the library's registry as it was."""
    import analysis.elements  # noqa: F401  (fills the registry first)

    saved = dict(ELEMENT_TYPES)
    register(_TestSpring)
    yield _TestSpring.kind
    ELEMENT_TYPES.clear()
    ELEMENT_TYPES.update(saved)


SIMPLE = """
title = "cantilever"
[nodes]
root = [0.0, 0.0]
mid = [0.5, 0.0]
tip = [1.0, 0.0]
[sections.bar]
shape = "rect"
b = 0.02
h = 0.01
[materials.steel]
E = "E"
rho = 7800.0
[[members]]
nodes = ["root", "mid"]
section = "bar"
material = "steel"
elements = 2
[[members]]
nodes = ["mid", "tip"]
section = "bar"
material = "steel"
elements = 2
[supports]
root = "all"
[points.1]
node = "tip"
direction = "y"
[parameters.E]
value = 2.0e11
nominal = 2.1e11
lower = 1e11
upper = 3e11
calibrate = true
unit = "Pa"
"""

FEATURES = """
title = "every feature"
[nodes]
a = [0.0, 0.0]
m1 = [0.5, 0.0]
b = [1.0, 0.0]
c = [1.0, 0.0]
d = [1.5, 0.5]
[sections.s1]
A = 1.0e-3
I = 1.0e-7
[sections.s2]
shape = "rect"
b = 0.02
h = 0.01
[materials.steel]
E = "E1"
rho = 7800.0
[[members]]
name = "m_ab"
nodes = ["a", "b"]
section = "s1"
material = "steel"
max_element_length = 0.2
nsm = "mu"
group = "g1"
[[members]]
nodes = ["c", "d"]
section = "s2"
material = "steel"
elements = 3
[[joints]]
name = "hinge"
nodes = ["b", "c"]
rz = "k_hinge"
[[springs]]
node = "d"
direction = "y"
k = 1.0e5
[[springs]]
node = "m1"
direction = "x"
k = "k_s"
to = "d"
[[masses]]
node = "d"
m = 0.5
J = 1.0e-3
[supports]
a = ["x", "y", "rz"]
[points.1]
xy = [0.5, 0.0]
direction = "y"
[points.2]
node = "d"
direction = "rz"
[parameters.E1]
value = 2.0e11
nominal = 2.1e11
lower = 1.0e11
upper = 3.0e11
[parameters.mu]
value = 1.0
lower = 0.0
upper = 5.0
[parameters.k_hinge]
value = 1.0e3
scaling = "log"
upper = 1.0e6
[parameters.k_s]
value = 1.0e4
[parameters.kc]
value = 1.0e6
[[nonlinear]]
name = "stop"
kind = "hertz_contact"
at = { point = 1 }
to = { node = "d", direction = "y" }
params = { k_c = "kc", gap = 1.0e-3, v = 0.0 }
options = { side = -1 }
[damping]
default_zeta = 0.02
[damping.per_mode]
2 = 0.05
"""


def test_features_parse_as_described():
    model = Model.from_toml_text(FEATURES)
    assert model.parameters["kc"].group == "nonlinear"
    assert model.parameters["k_s"].group == "linear"
    assert model.points[1].node == "m1" and model.points[1].xy == (0.5, 0.0)
    assert model.nonlinear[0].at == DofRef("m1", "y", 1)
    assert model.damping == DampingSpec(0.02, {2: 0.05})
    asm = model.assemble()
    # Joint: x and y tied, rz a spring with parameter k_hinge.
    assert asm.dof_index("b", "x") == asm.dof_index("c", "x")
    ib, ic = asm.dof_index("b", "rz"), asm.dof_index("c", "rz")
    assert ib != ic
    expected = np.zeros_like(asm.K)
    expected[np.ix_([ib, ic], [ib, ic])] = [[1.0, -1.0], [-1.0, 1.0]]
    np.testing.assert_array_equal(asm.dK["k_hinge"], expected)
    # Non-structural mass per metre: dM/dmu carries the 1 m member in a translation, less the
    # share of the supported node a: its first element (0.5 m / 3 for max 0.2 m) keeps only
    # the consistent-mass term 2/6 of its length on the free node.
    r = np.array([d == "x" for _, d in asm.dofs], dtype=float)
    first = 0.5 / 3
    assert r @ asm.dM["mu"] @ r == pytest.approx(1.0 - first + first / 3, rel=1e-12)
    report = asm.mass_report()
    assert report["g1 non-structural"] == pytest.approx(1.0, rel=1e-12)
    assert report["lumped"] == 0.5
    assert model.build_elements()[0][1].params == {"k_c": 1e6, "gap": 1e-3, "v": 0.0}


def test_supported_root_has_no_free_dofs():
    asm = Model.from_toml_text(FEATURES).assemble()
    for d in ("x", "y", "rz"):
        with pytest.raises(KeyError, match="a/"):
            asm.dof_index("a", d)


@pytest.mark.parametrize("text", [SIMPLE, FEATURES, None])
def test_round_trip(tmp_path, text):
    model = load_model() if text is None else Model.from_toml_text(text)
    model = model.add_masses({1: 0.02})
    path = model.save(tmp_path / "model.toml")
    again = load_model(path)
    assert again == model
    assert again.source == str(path)
    np.testing.assert_array_equal(again.assemble().K, model.assemble().K)


def error_text(tmp_path, text, **kwargs):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ModelFileError) as info:
        load_model(path, **kwargs)
    message = str(info.value)
    assert str(path) in message
    return message


BAD_SECTION = 'section = "tube90"\nmaterial = "steel"\nelements = 2\n[supports]'
ERRORS = {
    "unknown section": (
        'section = "bar"\nmaterial = "steel"\nelements = 2\n[supports]',
        BAD_SECTION,
        "members[1].section: unknown section 'tube90'",
    ),
    "missing parameter": (
        'E = "E"',
        'E = "E_missing"',
        "materials.steel.E: unknown parameter 'E_missing'",
    ),
    "bad direction": (
        'direction = "y"',
        'direction = "z"',
        "points.1.direction: bad direction 'z'",
    ),
    "point on no node": (
        'node = "tip"\ndirection',
        "xy = [0.33, 0.0]\ndirection",
        "points.1.xy: [0.33, 0.0] lies on no node",
    ),
    "negative density": (
        "rho = 7800.0",
        "rho = -7800.0",
        "materials.steel.rho: must be >= 0",
    ),
    "truth": (
        "[points.1]",
        "[truth]\nk_c = 4.51e5\n[points.1]",
        "truth: this model file holds the simulated truth",
    ),
    "unknown node": (
        'nodes = ["mid", "tip"]',
        'nodes = ["mid", "tap"]',
        "members[1].nodes: unknown node 'tap'",
    ),
    "no elements": (
        "elements = 2\n[supports]",
        "elements = 0\n[supports]",
        "members[1].elements: must be a positive",
    ),
    "bad scaling": (
        'unit = "Pa"',
        'unit = "Pa"\nscaling = "cubic"',
        "parameters.E.scaling: expected 'linear' or 'log', got 'cubic'",
    ),
    "unknown key": ("[points.1]", "[points.1]\nspeed = 3", "points.1: unknown key(s) 'speed'"),
    "bad TOML": ('title = "cantilever"', 'title = "cantilever', "invalid TOML"),
}


@pytest.mark.parametrize(("old", "new", "expected"), ERRORS.values(), ids=ERRORS.keys())
def test_errors_name_the_key_path_and_file(tmp_path, old, new, expected):
    assert old in SIMPLE
    assert expected in error_text(tmp_path, SIMPLE.replace(old, new, 1))


def test_truth_is_exposed_only_when_allowed(tmp_path):
    text = SIMPLE + "[truth]\nk_c = 4.51e5\ngap = 6.1e-4\n"
    error_text(tmp_path, text)
    model = load_model(tmp_path / "bad.toml", allow_truth=True)
    assert model.truth == {"k_c": 4.51e5, "gap": 6.1e-4}
    assert Model.from_toml_text(SIMPLE).truth is None
    assert Model.from_toml_text(model.to_toml(), allow_truth=True) == model


def test_nonlinear_reference_errors(test_kind):
    spec = NonlinearSpec("s", "model_file_test_spring", DofRef(point=1), params={"k": "k_x"})
    with pytest.raises(ModelFileError, match=r"nonlinear\[0\]\.params\.k: unknown parameter 'k_x'"):
        Model.from_toml_text(SIMPLE).with_nonlinear(spec)
    bad = NonlinearSpec("s", "no_such_kind", DofRef(point=1), params={})
    model = Model.from_toml_text(SIMPLE).with_nonlinear(bad)
    with pytest.raises(ModelFileError, match=r"nonlinear\[0\]\.kind: unknown element kind"):
        model.build_elements()
    wrong = NonlinearSpec("s", "model_file_test_spring", DofRef(point=1), params={"c": 1.0})
    with pytest.raises(ModelFileError, match=r"nonlinear\[0\].*unknown parameter"):
        Model.from_toml_text(SIMPLE).with_nonlinear(wrong).build_elements()
    far = NonlinearSpec("s", "model_file_test_spring", DofRef("root", "y"), params={"k": 1.0})
    with pytest.raises(ModelFileError, match=r"nonlinear\[0\]\.at: DOF root/y is not a free DOF"):
        Model.from_toml_text(SIMPLE).with_nonlinear(far)


def test_with_values():
    model = Model.from_toml_text(SIMPLE)
    with pytest.raises(ValueError, match=r"\['E_x', 'rho'\]"):
        model.with_values({"E_x": 1.0, "rho": 2.0, "E": 3e11})
    changed = model.with_values({"E": 2.5e11})
    assert changed.values() == {"E": 2.5e11} and model.values() == {"E": 2.0e11}
    base = model.assemble()
    # K is linear in E: K(E + dE) = K(E) + dE dK/dE.
    np.testing.assert_allclose(changed.assemble().K, base.K + 0.5e11 * base.dK["E"], rtol=1e-12)
    np.testing.assert_array_equal(changed.assemble().M, base.M)
    assert changed.assemble() is changed.assemble()  # cached
    with pytest.raises(ModelFileError, match=r"parameters\.E\.value: -1\.0 used by materials"):
        model.with_values({"E": -1.0})


def test_add_masses_raises_total_mass_exactly():
    model = load_model()
    sensors = {1: 0.0123, 7: 0.0231, 10: 0.0051}
    heavier = model.add_masses(sensors)
    before, after = model.assemble(), heavier.assemble()
    added = sum(sensors.values())
    assert after.mass_report()["sensors"] == pytest.approx(added, rel=1e-12)
    assert after.mass_report()["total"] == pytest.approx(
        before.mass_report()["total"] + added, rel=1e-12
    )
    for d in ("x", "y"):
        r = np.array([dof[1] == d for dof in after.dofs], dtype=float)
        assert r @ after.M @ r - r @ before.M @ r == pytest.approx(added, rel=1e-9)
    delta = after.M - before.M
    i7 = after.point_dof(7)
    assert delta[i7, i7] == pytest.approx(sensors[7], rel=1e-12)
    assert delta[after.point_dof(7, "rz"), after.point_dof(7, "rz")] == 0.0
    assert np.count_nonzero(delta) == 2 * len(sensors)
    with pytest.raises(ValueError, match="unknown measurement point 99"):
        model.add_masses({99: 0.01})
    with pytest.raises(ValueError, match="point 1"):
        model.add_masses({1: -0.01})


def test_with_and_without_nonlinear(test_kind):
    model = Model.from_toml_text(SIMPLE)
    spec = NonlinearSpec("spring", "model_file_test_spring", DofRef(point=1), params={"k": "k_t"})
    k_t = Parameter("k_t", 2.0e3, 2.0e3, 1.0, 1e6, calibrate=True)
    with_spring = model.with_nonlinear(spec, [k_t])
    assert with_spring.parameters["k_t"].group == "nonlinear"
    ((built_spec, element),) = with_spring.with_values({"k_t": 5.0e3}).build_elements()
    assert built_spec.at == DofRef("tip", "y", 1)
    assert element.params == {"k": 5.0e3}
    replaced = with_spring.with_nonlinear(
        NonlinearSpec("spring", "model_file_test_spring", DofRef("mid", "x"), params={"k": 7.0})
    )
    assert len(replaced.nonlinear) == 1 and replaced.nonlinear[0].at == DofRef("mid", "x")
    assert with_spring.without_nonlinear("spring").nonlinear == ()
    with pytest.raises(ValueError, match="no nonlinear element 'other'"):
        with_spring.without_nonlinear("other")
    damped = model.with_damping(DampingSpec(0.03, {1: 0.1}))
    assert damped.damping.zeta(3) == [0.1, 0.03, 0.03]
    assert damped.assemble() is model.assemble()  # same structure and values: shared cache


# -- the whole file is checked when it is loaded -----------------------------------------------
CONTACT = """
[parameters.k_c]
value = 4.5e5
lower = 1e4
upper = 1e7
[[nonlinear]]
name = "stop"
kind = "hertz_contact"
at = { point = 1 }
params = { k_c = "k_c", gap = 6e-4, v = 0.0 }
"""

LOAD_ERRORS = {
    "NaN coordinate": (SIMPLE.replace("tip = [1.0, 0.0]", "tip = [nan, 0.0]"), "nodes.tip[0]"),
    "infinite coordinate": (SIMPLE.replace("mid = [0.5, 0.0]", "mid = [0.5, inf]"), "nodes.mid[1]"),
    "node no element uses": (
        SIMPLE.replace("tip = [1.0, 0.0]", "tip = [1.0, 0.0]\nlost = [3.0, 1.0]"),
        "nodes.lost: no member, joint, spring or mass uses this node",
    ),
    "unknown element kind": (
        SIMPLE + CONTACT.replace("hertz_contact", "herz_contact"),
        "nonlinear[0].kind: unknown element kind 'herz_contact'",
    ),
    "unknown element parameter": (
        SIMPLE + CONTACT.replace("v = 0.0", "v = 0.0, damping = 3.0"),
        "nonlinear[0].params.damping: element 'hertz_contact': unknown parameter(s) ['damping']",
    ),
    "negative k_c": (
        SIMPLE + CONTACT.replace("value = 4.5e5\nlower = 1e4", "value = -4.5e5\nlower = -1e7"),
        "nonlinear[0].params.k_c: element 'hertz_contact': parameter 'k_c' must be > 0",
    ),
    "negative literal gap": (
        SIMPLE + CONTACT.replace("gap = 6e-4", "gap = -6e-4"),
        "nonlinear[0].params.gap: element 'hertz_contact': parameter 'gap' must be >= 0",
    ),
    "NaN literal element parameter": (
        SIMPLE + CONTACT.replace("gap = 6e-4", "gap = nan"),
        "nonlinear[0].params.gap: expected a finite number",
    ),
    "unicode digit point": (
        SIMPLE.replace("[points.1]", '[points."²"]'),
        "points.²: point numbers",
    ),
}


@pytest.mark.parametrize(("text", "expected"), LOAD_ERRORS.values(), ids=LOAD_ERRORS.keys())
def test_load_refuses_a_bad_model_with_file_and_key_path(tmp_path, text, expected):
    message = error_text(tmp_path, text)
    assert expected in message
    assert "LAPACK" not in message


def test_negative_k_c_names_the_model_parameter(tmp_path):
    text = SIMPLE + CONTACT.replace("value = 4.5e5\nlower = 1e4", "value = -4.5e5\nlower = -1e7")
    assert "parameters.k_c.value = -450000.0" in error_text(tmp_path, text)


def test_a_value_outside_its_bounds_is_a_warning_naming_it(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(SIMPLE + CONTACT.replace("value = 4.5e5", "value = 2e7\nnominal = 4.5e5"))
    with pytest.warns(ParameterBoundsWarning) as record:
        model = load_model(path)
    assert model.values()["k_c"] == 2e7
    (w,) = record
    text = str(w.message)
    assert str(path) in text and "parameters.k_c.value" in text
    assert "20000000.0" in text and "[10000.0, 10000000.0]" in text


def test_values_within_bounds_load_without_a_warning(recwarn):
    load_model()
    assert not [w for w in recwarn if issubclass(w.category, ParameterBoundsWarning)]


# -- the declared settings: shipped files, key paths as tuples -----------------------------
ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted([*ROOT.glob("analysis/models/*.toml"), *ROOT.glob("examples/*.toml")])


def test_the_paper_model_reads_to_the_values_its_file_gives():
    model = load_model(ROOT / "analysis/models/clearance_rig.toml")
    k_mount = model.parameters["k_mount"]
    assert (k_mount.value, k_mount.nominal, k_mount.lower, k_mount.upper) == (1e4, 1e4, 1e3, 1e6)
    assert (k_mount.scaling, k_mount.group, k_mount.calibrate) == ("log", "linear", True)
    assert model.parameters["gap"].group == "nonlinear"
    assert model.damping == DampingSpec(default_zeta=0.01) and model.damping.modal
    (stop,) = model.nonlinear
    assert (stop.kind, stop.at) == ("hertz_contact", DofRef("tip", "y", 7))
    assert stop.params == {"k_c": "k_c", "gap": "gap", "v": "v_c"}
    assert [m.elements for m in model.frame.members][:2] == [13, 7]


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_model_files_round_trip(tmp_path, path):
    model = load_model(path)
    again = load_model(model.save(tmp_path / path.name))
    assert again == model
    for p in model.parameters.values():
        assert build(Parameter, dump(p), "dump") == p
    assert build(DampingSpec, dump(model.damping), "dump") == model.damping


@pytest.mark.parametrize(
    ("old", "new", "path", "problem"),
    [
        ("lower = 1e11", "lower = nan", ("parameters", "E", "lower"), "must be a number"),
        ("lower = 1e11", "lower = 4e11", ("parameters", "E", "lower"), "must be below upper"),
        ("calibrate = true", "calibrate = 1", ("parameters", "E", "calibrate"), "true or false"),
        ('unit = "Pa"', 'unit = "Pa"\nprior_rel_std = 0.0', ("parameters", "E", "prior_rel_std"),
         "must be > 0"),
        ('direction = "y"', 'direction = "y"\nxy = [1.0, 2e4]', ("points", "1", "xy", 1),
         "must be <= 10000"),
        (ERRORS["unknown section"][0], BAD_SECTION, ("members", 1, "section"), "unknown section"),
        ("b = 0.02", "b = -0.02", ("sections", "bar", "b"), "must be a positive number"),
        ("elements = 2\n[supports]", "elements = 0\n[supports]", ("members", 1, "elements"),
         "must be a positive integer"),
        ("[parameters.E]", "[damping.per_mode]\n2 = 1.5\n[parameters.E]",
         ("damping", "per_mode", "2"), "must be < 1"),
        ("[parameters.E]", "[damping.per_mode]\nx = 0.1\n[parameters.E]",
         ("damping", "per_mode", "x"), "mode numbers start at 1"),
        ("[parameters.E]", "[damping.rayleigh]\nalpha = -1.0\n[parameters.E]",
         ("damping", "rayleigh", "alpha"), "must be >= 0, got -1.0"),
        ("[parameters.E]", "[damping]\nmatrix = [[1.0, 2.0]]\n[parameters.E]",
         ("damping", "matrix"), "square"),
    ],
)  # fmt: skip
def test_errors_carry_the_key_path_as_a_tuple(tmp_path, old, new, path, problem):
    assert old in SIMPLE
    file = tmp_path / "bad.toml"
    file.write_text(SIMPLE.replace(old, new, 1))
    with pytest.raises(ModelFileError, match=problem) as info:
        load_model(file)
    assert info.value.path == path
    assert str(info.value).startswith(f"{file}: {dotted(path)}: ")


def test_records_built_in_python_name_the_class_and_field():
    with pytest.raises(ValueError, match=r"Parameter\.nominal: 5\.0 is outside \[0\.0, 1\.0\]"):
        Parameter("p", 0.5, 5.0, 0.0, 1.0)
    with pytest.raises(ValueError, match=r"DampingSpec\.default_zeta: must be < 1"):
        DampingSpec(default_zeta=1.0)
    with pytest.raises(ValueError, match="give a point, or a node and a direction"):
        DofRef(node="tip")


# -- writing: from the declarations, read back to an equal model ---------------------------
TRUTHS = sorted((ROOT / "sim_backend/truths").glob("*.toml"))


def _truth(path: Path):
    def make(tmp_path: Path) -> Model:
        import sim_backend.hysteresis  # noqa: F401  (registers the simulator-only element kinds)

        return load_model(path, allow_truth=True)

    return make


def _loaded(text: str, tmp_path: Path) -> Model:
    path = tmp_path / "model.toml"
    path.write_text(text)
    return load_model(path)


def _damping_matrix(tmp_path: Path) -> Model:
    model = Model.from_toml_text(SIMPLE)
    C = 1e-4 * model.assemble().K + 0.1 * model.assemble().M
    return model.with_damping(DampingSpec(matrix=tuple(map(tuple, C))))


def _damping_matrix_file(tmp_path: Path) -> Model:
    model = Model.from_toml_text(SIMPLE)
    np.save(tmp_path / "C.npy", 1e-4 * model.assemble().K)
    return _loaded(SIMPLE + '[damping]\nmatrix = "C.npy"\n', tmp_path)


def _archive(tmp_path: Path) -> Model:
    from analysis.matrix_io import export_linear

    export_linear(Model.from_toml_text(SIMPLE), tmp_path / "simple.npz")
    text = '[linear_part]\nformat = "npz"\nfile = "simple.npz"\n[linear_part.masses]\ntip = 0.1\n'
    return _loaded(text + '[points.1]\nnode = "tip"\ndirection = "y"\n', tmp_path)


WRITTEN = {
    "reference": lambda tmp_path: load_model(),
    "features": lambda tmp_path: Model.from_toml_text(FEATURES),
    # kc stays in group "nonlinear" with no element using it: not what a reader would assume
    "unused parameter": lambda tmp_path: Model.from_toml_text(FEATURES).without_nonlinear("stop"),
    "rayleigh": lambda tmp_path: Model.from_toml_text(
        SIMPLE + "[damping]\nrayleigh = { alpha = 0.5, beta = 2e-5 }\n"
    ),
    "damping matrix": _damping_matrix,
    "damping matrix file": _damping_matrix_file,
    "linear part archive": _archive,
    **{f"examples/{p.name}": (lambda tmp_path, p=p: load_model(p)) for p in SHIPPED},
    **{f"truths/{p.name}": _truth(p) for p in TRUTHS},
}


@pytest.mark.parametrize("make", WRITTEN.values(), ids=WRITTEN.keys())
def test_the_written_file_reads_back_to_an_equal_model(tmp_path, make):
    model = make(tmp_path)
    again = Model.from_toml_text(model.to_toml(), str(tmp_path / "x.toml"), allow_truth=True)
    parts = ("parameters", "points", "nonlinear", "damping", "frame", "linear_part", "truth")
    for part in (*parts, "title"):
        assert getattr(again, part) == getattr(model, part), part
    saved = model.save(tmp_path / "saved.toml")
    assert load_model(saved, allow_truth=True) == model
    # infinite bounds are left out, not written as inf, null or a string
    for value in _scalars(tomllib.loads(saved.read_text())):
        assert not isinstance(value, float) or math.isfinite(value)
        assert str(value).lower() not in ("inf", "-inf", "infinity", "-infinity", "nan", "null")


def _scalars(value):
    if isinstance(value, dict | list):
        for item in value.values() if isinstance(value, dict) else value:
            yield from _scalars(item)
    else:
        yield value


def test_the_writer_leaves_out_what_a_reader_supplies(tmp_path):
    model = Model.from_toml_text(FEATURES)
    doc = to_document(model)
    # no bounds (infinite), no unit, no description, not calibrated, linear scaling, group
    # "linear": only the values
    assert doc["parameters"]["k_s"] == {"value": 1.0e4, "nominal": 1.0e4}
    assert doc["parameters"]["kc"] == {"value": 1.0e6, "nominal": 1.0e6, "group": "nonlinear"}
    assert doc["parameters"]["k_hinge"] == {
        "value": 1.0e3, "nominal": 1.0e3, "lower": 0.0, "upper": 1.0e6, "scaling": "log"
    }  # fmt: skip
    (stop,) = doc["nonlinear"]
    assert (stop["at"], stop["to"]) == ({"point": 1}, {"node": "d", "direction": "y"})
    assert doc["sections"] == {
        "s1": {"A": 1.0e-3, "I": 1.0e-7},
        "s2": {"shape": "rect", "b": 0.02, "h": 0.01},
    }
    assert doc["joints"] == [{"name": "hinge", "nodes": ["b", "c"], "rz": "k_hinge"}]
    assert doc["masses"] == [{"name": "mass0", "node": "d", "m": 0.5, "J": 1.0e-3}]
    assert doc["damping"] == {"default_zeta": 0.02, "per_mode": {"2": 0.05}}
    assert "damping" not in to_document(load_model())  # the declared default damping
    assert to_document(_damping_matrix_file(tmp_path), tmp_path)["damping"] == {"matrix": "C.npy"}
    at_x = NonlinearSpec("s", "hertz_contact", DofRef(point=1, direction="x"), params={})
    assert to_document(model.with_nonlinear(at_x))["nonlinear"][-1]["at"] == {
        "direction": "x", "point": 1
    }  # fmt: skip
