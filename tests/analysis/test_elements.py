"""Tests of the nonlinear element library ``analysis.elements``.

References are independent of the implementation: central finite differences for every
derivative, the closed-form laws of ``docs/rig.md`` and the element brief written out with scalar
``math`` at chosen points, and mirror/averaging identities.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np
import pytest

import analysis.elements as elements
from analysis.elements import (
    ELEMENT_TYPES,
    ElementEval,
    NonlinearElement,
    element_summary,
    make_element,
    register,
)

# Typical values for each kind (docs/rig.md's calibrated contact, stiffnesses of the same order),
# the displacement scale [m] and velocity scale [m/s] the samples are drawn from.
EXAMPLES: list[tuple[str, dict, float, float]] = [
    ("hertz_contact", {"k_c": 4.51e5, "gap": 6.1e-4, "v": 25.21}, 2e-3, 0.2),
    ("hertz_contact", {"k_c": 1e6, "gap": 1e-3, "v": 10.0, "side": 1}, 3e-3, 0.2),
    ("gap_spring", {"k": 2e5, "gap": 6e-4}, 2e-3, 0.2),
    ("gap_spring", {"k": 2e5, "gap": 6e-4, "side": 1}, 2e-3, 0.2),
    ("two_sided_gap", {"k": 3e5, "gap": 5e-4}, 2e-3, 0.2),
    ("bilinear_spring", {"k_pos": 1e4, "k_neg": 5e4}, 2e-3, 0.2),
    ("linear_spring", {"k": 5.8e4}, 2e-3, 0.2),
    ("quadratic_spring", {"k2": 2e6}, 2e-3, 0.2),
    ("cubic_spring", {"k3": -3e9}, 2e-3, 0.2),
    (
        "polynomial_spring",
        {"k1": 1e4, "k2": 1e6, "k3": 1e9, "k4": -1e11, "k5": 1e13},
        3e-3,
        0.2,
    ),
    ("polynomial_spring", {"k2": -4e5, "k5": 2e13}, 3e-3, 0.2),
    ("linear_damper", {"c": 12.0}, 2e-3, 0.2),
    ("quadratic_damper", {"c2": 25.0}, 2e-3, 0.2),
    ("cubic_damper", {"c3": 300.0}, 2e-3, 0.2),
    ("coulomb_friction", {"f_slip": 1.5}, 2e-3, 4e-3),
    ("coulomb_friction", {"f_slip": 0.7, "v_reg": 0.02}, 2e-3, 0.1),
]
EXAMPLE_IDS = [f"{kind}-{i}" for i, (kind, *_) in enumerate(EXAMPLES)]

RTOL_FD = 1e-6  # finite-difference agreement, relative to the largest |derivative| sampled


def _sign(x: float) -> float:
    return math.copysign(1.0, x) if x != 0 else 0.0


def _hertz(p: dict, u: float, vel: float) -> float:
    k_c, d, c, side = p["k_c"], p["gap"], p["v"], p.get("side", -1)
    if side == -1:  # docs/rig.md, literally
        return k_c * (abs(u) - d) ** 1.5 - c * vel * abs(vel) if u < -d else 0.0
    return -k_c * (u - d) ** 1.5 - c * vel * abs(vel) if u > d else 0.0


def _gap_spring(p: dict, u: float, vel: float) -> float:
    k, d, side = p["k"], p["gap"], p.get("side", -1)
    if side == -1:
        return k * (-u - d) if u < -d else 0.0
    return -k * (u - d) if u > d else 0.0


def _two_sided(p: dict, u: float, vel: float) -> float:
    k, d = p["k"], p["gap"]
    return -k * (u - d) if u > d else (-k * (u + d) if u < -d else 0.0)


def _polynomial(p: dict, u: float, vel: float) -> float:
    return -sum(p.get(f"k{j}", 0.0) * u**j for j in range(1, 6))


# Closed-form laws evaluated with scalar math: kind -> f(params and options, u, vel).
REFERENCE_LAWS: dict[str, Callable[[dict, float, float], float]] = {
    "hertz_contact": _hertz,
    "gap_spring": _gap_spring,
    "two_sided_gap": _two_sided,
    "bilinear_spring": lambda p, u, vel: -(p["k_pos"] if u > 0 else p["k_neg"]) * u,
    "linear_spring": lambda p, u, vel: -p["k"] * u,
    "quadratic_spring": lambda p, u, vel: -p["k2"] * u * u,
    "cubic_spring": lambda p, u, vel: -p["k3"] * u**3,
    "polynomial_spring": _polynomial,
    "linear_damper": lambda p, u, vel: -p["c"] * vel,
    "quadratic_damper": lambda p, u, vel: -p["c2"] * vel * abs(vel),
    "cubic_damper": lambda p, u, vel: -p["c3"] * vel**3,
    "coulomb_friction": lambda p, u, vel: -p["f_slip"] * math.tanh(vel / p.get("v_reg", 1e-3)),
}


def _samples(values: dict, u_scale: float, v_scale: float, n: int = 400, seed: int = 7):
    """Random (u, v) at least 1 % of the scale away from every switching point."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-u_scale, u_scale, n)
    v = rng.uniform(-v_scale, v_scale, n)
    gap = values.get("gap", 0.0)
    switches = np.array([0.0, gap, -gap])
    far = (np.min(np.abs(u[:, None] - switches), axis=1) > 0.01 * u_scale) & (
        np.abs(v) > 0.01 * v_scale
    )
    assert far.sum() > n // 2
    return u[far], v[far]


def _assert_close(analytic: np.ndarray, fd: np.ndarray, what: str) -> None:
    scale = max(np.max(np.abs(analytic)), np.max(np.abs(fd)), 1e-300)
    np.testing.assert_allclose(analytic, fd, rtol=RTOL_FD, atol=RTOL_FD * scale, err_msg=what)


def check_derivatives(
    el: NonlinearElement, u: np.ndarray, v: np.ndarray, u_scale: float, v_scale: float
) -> None:
    """df_du, df_dv and df_dp of ``el`` against central finite differences."""
    ev = el.evaluate(u, v, want_params=True)
    assert np.count_nonzero(ev.f) >= 20, "samples never load the element"
    hu, hv = 1e-7 * u_scale, 1e-7 * v_scale
    _assert_close(ev.df_du, (el.force(u + hu, v) - el.force(u - hu, v)) / (2 * hu), "df_du")
    _assert_close(ev.df_dv, (el.force(u, v + hv) - el.force(u, v - hv)) / (2 * hv), "df_dv")
    assert ev.df_dp.shape == (len(el.param_names), *u.shape)
    for i, (name, value) in enumerate(el.params.items()):
        # Relative step; a zero parameter gets the step that changes f by about 1e-6 of |f|.
        zero_step = 1e-6 * np.max(np.abs(ev.f)) / max(np.max(np.abs(ev.df_dp[i])), 1e-300)
        h = 1e-7 * abs(value) if value != 0 else zero_step
        up = el.with_params(**{name: value + h}).force(u, v)
        down = el.with_params(**{name: value - h}).force(u, v)
        _assert_close(ev.df_dp[i], (up - down) / (2 * h), f"df_d{name}")


def _build(kind: str, values: dict) -> NonlinearElement:
    return make_element(kind, **values)


# -- every registered kind --------------------------------------------------------------------


def test_examples_cover_every_registered_kind():
    # the library's own kinds (a package may register more, e.g. the simulator's Jenkins element)
    library = {k for k, cls in ELEMENT_TYPES.items() if cls.__module__.startswith("analysis.")}
    assert {kind for kind, *_ in EXAMPLES} == library


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_derivatives_match_central_differences(kind, values, u_scale, v_scale):
    el = _build(kind, values)
    u, v = _samples(values, u_scale, v_scale)
    check_derivatives(el, u, v, u_scale, v_scale)


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_every_law_has_a_compiled_form_equal_to_its_array_code(kind, values, u_scale, v_scale):
    """The balance evaluates the compiled law; the array code gives the parameter
    derivatives. Both at random samples and at the switching points themselves, where a law
    takes its open side: equal to rounding (``tanh`` and ``pow`` of two libraries differ in
    the last place; a polynomial's terms cancel, so 4 ulp of the largest value sampled)."""
    el = _build(kind, values)
    assert el.compiled_law() is not None
    u, v = _samples(values, u_scale, v_scale)
    gap = values.get("gap", 0.0)
    u = np.concatenate([u, [0.0, gap, -gap, 0.0]])
    v = np.concatenate([v, [0.0, 0.0, v_scale, -v_scale]])
    fast, ref = el.evaluate(u, v), el.evaluate(u, v, want_params=True)
    for name in ("f", "df_du", "df_dv"):
        a, r = getattr(fast, name), getattr(ref, name)
        np.testing.assert_allclose(a, r, rtol=0.0, atol=9e-16 * np.abs(r).max(), err_msg=name)


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_vectorised_shapes_match_pointwise(kind, values, u_scale, v_scale):
    el = _build(kind, values)
    u_flat, v_flat = _samples(values, u_scale, v_scale, n=40)
    u_flat, v_flat = u_flat[:12], v_flat[:12]
    flat = el.evaluate(u_flat, v_flat, want_params=True)
    for shape in [(), (12,), (3, 4)]:
        n = math.prod(shape)
        u, v = u_flat[:n].reshape(shape), v_flat[:n].reshape(shape)
        ev = el.evaluate(u, v, want_params=True)
        for name in ("f", "df_du", "df_dv"):
            got = getattr(ev, name)
            assert isinstance(got, np.ndarray) and got.shape == shape, name
            np.testing.assert_array_equal(got.ravel(), getattr(flat, name)[:n], err_msg=name)
        assert ev.df_dp.shape == (len(el.param_names), *shape)
        np.testing.assert_array_equal(ev.df_dp.reshape(len(el.param_names), n), flat.df_dp[:, :n])
        assert el.evaluate(u, v).df_dp is None


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_with_params_round_trip(kind, values, u_scale, v_scale):
    el = _build(kind, values)
    same = el.with_params(**el.params)
    assert type(same) is type(el) and same.params == el.params and same.options == el.options
    name = el.param_names[0]
    new_value = 2.0 * el.params[name] + 1.0
    changed = el.with_params(**{name: new_value})
    assert changed.params == {**el.params, name: new_value}
    assert changed.options == el.options
    assert el.params[name] != new_value  # the original is untouched
    np.testing.assert_array_equal(changed.p, list(changed.params.values()))


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_repr_names_everything_and_round_trips(kind, values, u_scale, v_scale):
    el = _build(kind, values)
    text = repr(el)
    cls = ELEMENT_TYPES[kind]
    assert text.startswith(f"{cls.__name__}(")
    for name in (*el.param_names, *el.option_names):
        assert f"{name}=" in text
    back = eval(text, {cls.__name__: cls})  # the repr of our own object
    assert back.params == el.params and back.options == el.options


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_law_matches_closed_form(kind, values, u_scale, v_scale):
    el = _build(kind, values)
    gap = values.get("gap", 0.0)
    points_u = sorted(
        {*(s * u_scale for s in (-1.0, -0.37, 0.0, 0.41, 1.0)), -gap, gap, -1.5 * gap, 1.5 * gap}
    )
    points_v = [-v_scale, -0.3 * v_scale, 0.0, 0.6 * v_scale]
    law = REFERENCE_LAWS[kind]
    for u in points_u:
        for v in points_v:
            expected = law(values, u, v)
            assert float(el.force(u, v)) == pytest.approx(expected, rel=1e-12, abs=1e-300), (u, v)


# -- sign conventions and branches ------------------------------------------------------------

HERTZ = {"k_c": 4.51e5, "gap": 6.1e-4, "v": 25.21}


def test_contact_pushes_the_tip_up_below_the_gap_only():
    el = make_element("hertz_contact", **HERTZ)
    d = HERTZ["gap"]
    below = -d - np.linspace(1e-6, 2e-3, 50)
    assert np.all(el.force(below, np.zeros_like(below)) > 0)
    outside = np.linspace(-d, 5e-3, 50)  # includes the switch u = -gap itself
    for vel in (-0.3, 0.0, 0.3):
        ev = el.evaluate(outside, np.full_like(outside, vel), want_params=True)
        assert np.all(ev.f == 0) and np.all(ev.df_du == 0) and np.all(ev.df_dv == 0)
        assert np.all(ev.df_dp == 0)


def test_contact_mirror_side_is_point_symmetric():
    below = make_element("hertz_contact", **HERTZ)
    above = below.with_params(side=1)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-3e-3, 3e-3, 200), rng.uniform(-0.3, 0.3, 200)
    np.testing.assert_array_equal(above.force(u, v), -below.force(-u, -v))
    assert np.all(above.force(u[u > HERTZ["gap"]], 0 * u[u > HERTZ["gap"]]) < 0)
    assert np.all(above.force(u[u <= HERTZ["gap"]], v[u <= HERTZ["gap"]]) == 0)


def test_contact_damping_pulls_while_leaving_and_jumps_at_entry():
    el = make_element("hertz_contact", **HERTZ)
    c, d = HERTZ["v"], HERTZ["gap"]
    pen, vel = 1e-6, 0.2  # small penetration, moving up (leaving the stop)
    f = float(el.force(-d - pen, vel))
    assert f < 0
    assert f == pytest.approx(HERTZ["k_c"] * pen**1.5 - c * vel**2, rel=1e-12)
    # Entering (moving down) at the switch: the force jumps from 0 to about +c vel^2.
    jump = float(el.force(-d - 1e-12, -vel)) - float(el.force(-d, -vel))
    assert jump == pytest.approx(c * vel**2, rel=1e-6)


@pytest.mark.parametrize("kind", ["gap_spring", "two_sided_gap"])
def test_gap_laws_are_zero_inside_the_clearance(kind):
    el = make_element(kind, k=2e5, gap=6e-4)
    u = np.linspace(-6e-4, 6e-4, 101)  # both switches included
    ev = el.evaluate(u, np.full_like(u, 0.3), want_params=True)
    assert np.all(ev.f == 0) and np.all(ev.df_du == 0) and np.all(ev.df_dp == 0)
    assert float(el.force(-1e-3, 0.0)) == pytest.approx(2e5 * 4e-4, rel=1e-12)  # pushes up


def test_gap_spring_sides_and_two_sided_gap_are_consistent():
    below = make_element("gap_spring", k=2e5, gap=6e-4)
    above = below.with_params(side=1)
    both = make_element("two_sided_gap", k=2e5, gap=6e-4)
    u = np.linspace(-3e-3, 3e-3, 301)
    v = np.zeros_like(u)
    np.testing.assert_array_equal(above.force(u, v), -below.force(-u, v))
    np.testing.assert_allclose(both.force(u, v), above.force(u, v) + below.force(u, v), rtol=0)
    assert np.all(above.force(u[u > 6e-4], v[u > 6e-4]) < 0)
    assert np.all(np.diff(both.force(u, v)) <= 0)  # a restoring (monotone) law


def test_bilinear_spring_uses_k_neg_at_zero():
    el = make_element("bilinear_spring", k_pos=1e4, k_neg=5e4)
    ev = el.evaluate(0.0, 0.0, want_params=True)
    assert ev.f == 0 and ev.df_du == -5e4
    np.testing.assert_array_equal(ev.df_dp, [0.0, -0.0])


def test_quadratic_spring_gives_the_closed_form_mean_force():
    # <-k2 (A sin t)^2> over a period = -k2 A^2 / 2 (uniform samples integrate exactly).
    k2, amp = 2e6, 1.3e-3
    el = make_element("quadratic_spring", k2=k2)
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    mean = el.force(amp * np.sin(t), amp * np.cos(t)).mean()
    assert mean == pytest.approx(-k2 * amp**2 / 2, rel=1e-12)


def test_polynomial_spring_defaults_omitted_coefficients_to_zero():
    el = make_element("polynomial_spring", k3=1e9)
    assert el.params == {"k1": 0.0, "k2": 0.0, "k3": 1e9, "k4": 0.0, "k5": 0.0}
    u = np.linspace(-2e-3, 2e-3, 9)
    np.testing.assert_allclose(
        el.force(u, u), make_element("cubic_spring", k3=1e9).force(u, u), rtol=1e-15
    )


def test_dampers_oppose_the_velocity_and_ignore_displacement():
    rng = np.random.default_rng(5)
    u, v = rng.uniform(-1e-2, 1e-2, 100), rng.uniform(-0.5, 0.5, 100)
    for kind, name in [
        ("linear_damper", "c"),
        ("quadratic_damper", "c2"),
        ("cubic_damper", "c3"),
        ("coulomb_friction", "f_slip"),
    ]:
        el = make_element(kind, **{name: 3.0})
        ev = el.evaluate(u, v)
        assert np.all(ev.f * v < 0), kind
        np.testing.assert_array_equal(ev.f, el.force(np.zeros_like(u), v))
        assert np.all(ev.df_du == 0)


def test_coulomb_friction_saturates_at_the_slip_force():
    el = make_element("coulomb_friction", f_slip=1.5, v_reg=1e-3)
    assert float(el.force(0.0, 0.05)) == pytest.approx(-1.5, rel=1e-12)  # tanh(50)
    assert float(el.evaluate(0.0, 0.0).df_dv) == pytest.approx(-1.5 / 1e-3, rel=1e-12)


# -- errors -----------------------------------------------------------------------------------


def _raises_naming(kind: str, words: list[str], **values) -> None:
    with pytest.raises(ValueError) as info:
        make_element(kind, **values)
    message = str(info.value)
    for word in [repr(kind), *words]:
        assert word in message, (word, message)


def test_unknown_and_missing_parameters_are_named():
    _raises_naming("hertz_contact", ["'stiffness'", "k_c", "side"], stiffness=1.0, gap=0.0, v=1.0)
    _raises_naming("hertz_contact", ["missing", "'gap'"], k_c=1e6, v=1.0)
    _raises_naming("linear_spring", ["missing", "'k'"])


@pytest.mark.parametrize("bad", ["abc", "1.0", None, True, [1.0, 2.0], float("nan"), np.inf])
def test_non_numeric_or_non_finite_values_are_refused(bad):
    _raises_naming("hertz_contact", ["'gap'"], k_c=1e6, gap=bad, v=1.0)


@pytest.mark.parametrize(
    ("kind", "values", "words"),
    [
        ("hertz_contact", {"k_c": 1e6, "gap": -1e-4, "v": 1.0}, ["'gap'", ">= 0"]),
        ("hertz_contact", {"k_c": 0.0, "gap": 1e-4, "v": 1.0}, ["'k_c'", "> 0"]),
        ("hertz_contact", {"k_c": 1e6, "gap": 1e-4, "v": -1.0}, ["'v'", ">= 0"]),
        ("hertz_contact", {"k_c": 1e6, "gap": 1e-4, "v": 1.0, "side": 0}, ["'side'", "-1"]),
        ("gap_spring", {"k": 1e5, "gap": 1e-4, "side": "up"}, ["'side'", "number"]),
        ("gap_spring", {"k": -1e5, "gap": 1e-4}, ["'k'", "> 0"]),
        ("two_sided_gap", {"k": 1e5, "gap": -1e-4}, ["'gap'", ">= 0"]),
        ("bilinear_spring", {"k_pos": -1.0, "k_neg": 1.0}, ["'k_pos'", ">= 0"]),
        ("linear_damper", {"c": -1.0}, ["'c'", ">= 0"]),
        ("quadratic_damper", {"c2": -1.0}, ["'c2'", ">= 0"]),
        ("cubic_damper", {"c3": -1.0}, ["'c3'", ">= 0"]),
        ("coulomb_friction", {"f_slip": -1.0}, ["'f_slip'", ">= 0"]),
        ("coulomb_friction", {"f_slip": 1.0, "v_reg": 0.0}, ["'v_reg'", "> 0"]),
        ("coulomb_friction", {"f_slip": 1.0, "v_reg": None}, ["'v_reg'", "number"]),
    ],
)
def test_invalid_values_are_named(kind, values, words):
    _raises_naming(kind, words, **values)


def test_numpy_and_integer_values_are_accepted():
    el = make_element("hertz_contact", k_c=np.float64(1e6), gap=np.float32(0.5e-3), v=10, side=1.0)
    assert el.options["side"] == 1 and isinstance(el.params["v"], float)


def test_unknown_kind_lists_the_known_kinds():
    with pytest.raises(ValueError, match="'bump_stop'") as info:
        make_element("bump_stop", k=1.0)
    for kind in ELEMENT_TYPES:
        assert repr(kind) in str(info.value)


def test_mismatched_sample_shapes_are_refused():
    el = make_element("linear_spring", k=1.0)
    with pytest.raises(ValueError, match="'linear_spring'.*shapes differ"):
        el.evaluate(np.zeros(3), np.zeros(4))


# -- summary and extensibility ----------------------------------------------------------------


def test_element_summary_describes_every_kind():
    summary = element_summary()
    assert [entry["kind"] for entry in summary] == sorted(ELEMENT_TYPES)
    for entry in summary:
        cls = ELEMENT_TYPES[entry["kind"]]
        assert entry["class"] == cls.__name__ and entry["description"]
        assert [(q["name"], q["unit"]) for q in entry["params"]] == list(
            zip(cls.param_names, cls.param_units, strict=True)
        )
        assert entry["options"] == cls.option_names
    contact = next(e for e in summary if e["kind"] == "hertz_contact")
    assert [q["constraint"] for q in contact["params"]] == ["> 0", ">= 0", ">= 0"]
    assert contact["options"] == {"side": -1}


@pytest.fixture
def scratch_registry() -> Iterator[None]:
    """Let a test register kinds without leaking them to other tests."""
    saved = dict(ELEMENT_TYPES)
    yield
    ELEMENT_TYPES.clear()
    ELEMENT_TYPES.update(saved)


def test_a_new_kind_is_one_small_subclass(scratch_registry):
    @register
    class SaturatingSpring(NonlinearElement):
        """``f = -k u0 tanh(u / u0)``."""

        kind = "saturating_spring"
        param_names = ("k", "u0")
        param_units = ("N/m", "m")
        positive_params = ("u0",)
        description = "spring whose force saturates at k u0"

        def _evaluate(self, u, v, want_params):
            k, u0 = self._p
            t = np.tanh(u / u0)
            df_du = -k * (1 - t * t)
            df_dp = np.stack([-u0 * t, -k * t - u * df_du / u0]) if want_params else None
            return ElementEval(-k * u0 * t, df_du, np.zeros_like(u), df_dp)

    el = make_element("saturating_spring", k=1e5, u0=1e-3)
    assert isinstance(el, SaturatingSpring) and "saturating_spring" in elements.ELEMENT_TYPES
    assert float(el.force(1.0, 0.0)) == pytest.approx(-100.0, rel=1e-12)  # saturated
    u, v = _samples({}, 3e-3, 0.1)
    check_derivatives(el, u, v, 3e-3, 0.1)
    assert any(e["kind"] == "saturating_spring" for e in element_summary())
    _raises_naming("saturating_spring", ["'u0'", "> 0"], k=1.0, u0=0.0)


def test_register_refuses_inconsistent_classes(scratch_registry):
    with pytest.raises(TypeError, match="kind"):
        register(type("NoKind", (NonlinearElement,), {}))
    with pytest.raises(TypeError, match="registered twice"):
        register(type("Clash", (NonlinearElement,), {"kind": "linear_spring"}))
    with pytest.raises(TypeError, match="param_units"):
        register(type("NoUnits", (NonlinearElement,), {"kind": "x1", "param_names": ("k",)}))
    assert "x1" not in ELEMENT_TYPES
