"""Fuzzing the three file readers with mutated valid documents (seeded, reproducible).

Every mutated input must either load (and then round-trip) or be refused with the project's
own error naming the file: a :class:`~analysis.model_file.ModelFileError` for a model file, a
:class:`~rig.config.tomlconfig.ConfigError` for a plan or a setup, a
:class:`~analysis.measurement_file.MeasurementFileError` for a measurement file. Never a
traceback of another type, never a NaN or an infinity accepted in silence.
"""

from __future__ import annotations

import copy
import math
import random
import shutil
import tomllib
import warnings
from typing import Any

import h5py
import numpy as np
import pytest
import tomli_w

from analysis.measurement_file import MeasurementFileError, read_measurement
from analysis.model import Model, ModelFileError
from rig.config.plans import builtin_plans, plan_from_dict
from rig.config.setup import builtin_setups, setup_from_dict
from rig.config.tomlconfig import ConfigError
from tests.analysis import measurement_samples as ms

N_CASES = 1000

# -- mutating parsed TOML documents ------------------------------------------------------------
_ODD_VALUES: list[Any] = [
    math.nan,
    math.inf,
    -math.inf,
    1e308,
    -1e308,
    10**30,
    -(10**30),
    -1,
    -1.0,
    0,
    0.0,
    1e-320,
    True,
    False,
    "",
    "bogus",
    "nan",
    " ",
    "\u00e9\u00b2",
    [],
    [1, 2],
    ["a"],
    {},
    {"x": 1},
    2**63 - 1,
    3.5,
    7,
]


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path (dict keys and list indices) in ``doc``."""
    out = []
    items = (
        doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    )
    for k, v in items:
        out.append((*prefix, k))
        out += _paths(v, (*prefix, k))
    return out


def _has_non_finite(value: Any) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, dict):
        return any(_has_non_finite(v) for v in value.values())
    if isinstance(value, list):
        return any(_has_non_finite(v) for v in value)
    return False


def mutate(doc: dict, rng: random.Random) -> tuple[dict, str, bool]:
    """A copy of ``doc`` with 1-3 mutations; returns (doc, description, a non-finite was put)."""
    doc = copy.deepcopy(doc)
    what, non_finite = [], False
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        paths = _paths(doc)
        if not paths:
            break
        path = rng.choice(paths)
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        key = path[-1]
        old = parent[key]
        op = rng.random()
        if op < 0.25:
            del parent[key]
            what.append(f"delete {path}")
            continue
        if op < 0.35 and isinstance(old, int | float) and not isinstance(old, bool):
            new = old * rng.choice((-1, 0, 1e12, -1e-12, 1.0000001))
        elif op < 0.45 and isinstance(old, str):
            new = old + rng.choice(("x", " ", "/", "-", "\u00e9")) if old else "y"
        elif op < 0.55 and isinstance(parent, dict):
            parent[key + rng.choice(("_", "x", "2"))] = old  # a misspelt duplicate key
            what.append(f"copy {path} under a misspelt key")
            continue
        else:
            new = copy.deepcopy(rng.choice(_ODD_VALUES))
        parent[key] = new
        open_bound = key in ("lower", "upper") and isinstance(new, float) and math.isinf(new)
        non_finite |= _has_non_finite(new) and not open_bound  # an infinite bound is no bound
        what.append(f"set {path} = {new!r}")
    return doc, "; ".join(what), non_finite


def _run_toml_fuzz(base: dict, load, check_loaded, error_type, name: str, seed: int, tmp_path):
    """Feed ``N_CASES`` mutations of ``base`` to ``load(doc, source)``; collect failures."""
    rng = random.Random(seed)
    failures, loaded, refused = [], 0, 0
    for case in range(N_CASES):
        doc, what, non_finite = mutate(base, rng)
        source = f"{name}-case{case}"
        if case % 10 == 0:  # through a real file now and then (TOML writing and parsing)
            try:
                text = tomli_w.dumps(doc)
            except (TypeError, ValueError):
                continue
            path = tmp_path / f"{source}.toml"
            path.write_text(text)
            doc, source = tomllib.loads(text), str(path)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = load(doc, source)
        except error_type as exc:
            refused += 1
            if source not in str(exc):
                failures.append(f"{what}: message does not name {source}: {exc}")
            continue
        except Exception as exc:  # noqa: BLE001 - exactly what the fuzzer hunts
            failures.append(f"{what}: {type(exc).__name__}: {exc}")
            continue
        loaded += 1
        if non_finite:
            failures.append(f"{what}: a NaN or infinity was accepted")
            continue
        try:
            check_loaded(result, source)
        except Exception as exc:  # noqa: BLE001
            failures.append(f"{what}: loaded but does not round-trip: {type(exc).__name__}: {exc}")
    assert not failures, f"{len(failures)} failures, e.g.\n" + "\n".join(failures[:15])
    assert refused > N_CASES // 4 and loaded > 10, (loaded, refused)


# -- model file ----------------------------------------------------------------------------------
MODEL_TEXT = """
title = "cantilever with a stop"
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
[[springs]]
node = "tip"
direction = "x"
k = 1e6
[[masses]]
node = "tip"
m = 0.1
[supports]
root = "all"
[points.1]
node = "tip"
direction = "y"
[parameters.E]
value = 2.0e11
lower = 1e11
upper = 3e11
calibrate = true
[parameters.k_c]
value = 4.5e5
lower = 1e4
upper = 1e7
scaling = "log"
[damping]
default_zeta = 0.01
per_mode = { 1 = 0.02 }
[[nonlinear]]
name = "stop"
kind = "hertz_contact"
at = { point = 1 }
params = { k_c = "k_c", gap = 6e-4, v = 0.0 }
"""


def _model_round_trip(model: Model, source: str) -> None:
    again = Model.from_toml_text(model.to_toml(), source)
    assert again == model
    model.assemble()


def test_fuzz_model_file(tmp_path):
    base = tomllib.loads(MODEL_TEXT)
    _model_round_trip(Model.from_toml_text(MODEL_TEXT), "base")

    def load(doc, source):
        return Model.from_toml_text(tomli_w.dumps(doc), source)

    _run_toml_fuzz(base, load, _model_round_trip, ModelFileError, "model", 1, tmp_path)


# -- plans and setups --------------------------------------------------------------------------
def _plan_round_trip(plan, source):
    assert plan_from_dict(plan.to_dict(), source) == plan


def _setup_round_trip(setup, source):
    assert setup_from_dict(setup.to_dict(), source) == setup


@pytest.mark.parametrize("name", ["paper", "quick", "linear"])
def test_fuzz_plan_files(tmp_path, name):
    base = tomllib.loads(builtin_plans()[name].read_text())
    _run_toml_fuzz(base, plan_from_dict, _plan_round_trip, ConfigError, f"plan-{name}", 2, tmp_path)


def test_fuzz_setup_file(tmp_path):
    base = tomllib.loads(builtin_setups()["reference"].read_text())
    _run_toml_fuzz(base, setup_from_dict, _setup_round_trip, ConfigError, "setup", 3, tmp_path)


# -- measurement files -------------------------------------------------------------------------
def _objects(f: h5py.File) -> list[tuple[str, str | None]]:
    """(object path, attribute name or None) for every dataset, group and attribute."""
    out: list[tuple[str, str | None]] = [("/", a) for a in f.attrs]

    def visit(name, obj):
        out.append((f"/{name}", None))
        out.extend((f"/{name}", a) for a in obj.attrs)

    f.visititems(visit)
    return out


_ODD_ARRAYS: list[Any] = [
    np.float64(np.nan),
    np.array([np.inf, 1.0]),
    np.array([[1, 2], [3, 4]]),
    np.zeros(0),
    np.array([-1, -5]),
    np.int64(-1),
    np.int64(2**62),
    np.float64(1e308),
    "bogus",
    np.array(["a", "b"], dtype=h5py.string_dtype()),
    np.bool_(True),
    np.array([1 + 2j]),
    np.float32(3.5),
    b"\xff\xfe",
    "{not json",
    '{"a": NaN}',
    "[]",
    "{}",
]


def _mutate_h5(f: h5py.File, rng: random.Random) -> str:
    where, attr = rng.choice(_objects(f))
    op = rng.random()
    if attr is not None:
        if op < 0.3:
            del f[where].attrs[attr]
            return f"delete attribute {where}@{attr}"
        new = rng.choice(_ODD_ARRAYS)
        f[where].attrs[attr] = new
        return f"set attribute {where}@{attr} = {new!r}"
    if where == "/":
        return "nothing"
    obj = f[where]
    if op < 0.3 or not isinstance(obj, h5py.Dataset):
        del f[where]
        return f"delete {where}"
    data = obj[()]
    if op < 0.55 and isinstance(data, np.ndarray) and data.size and data.dtype.kind in "fciu":
        data = data.copy()
        flat = data.reshape(-1)
        i = rng.randrange(flat.size)
        value = rng.choice((np.nan, np.inf, -np.inf, -1, 1e300, 0, 2**40))
        if data.dtype.kind in "iu":
            info = np.iinfo(data.dtype)
            value = info.min if not math.isfinite(value) else min(max(value, info.min), info.max)
        flat[i] = value
        del f[where]
        f.create_dataset(where, data=data)
        return f"set {where}[{i}] = {value}"
    if op < 0.7 and isinstance(data, np.ndarray) and data.ndim:
        cut = data[: rng.randrange(data.shape[0] + 1)]
        del f[where]
        f.create_dataset(where, data=cut)
        return f"truncate {where} to {cut.shape}"
    new = rng.choice(_ODD_ARRAYS)
    del f[where]
    f.create_dataset(where, data=new)
    return f"replace {where} by {new!r}"


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["stepped-sine", "random"])
def test_fuzz_measurement_file(tmp_path, kind):
    base = tmp_path / "base.h5"
    if kind == "stepped-sine":
        ms.write_sample_stepped_sine(base)
    else:
        ms.write_sample_random(base)
    read_measurement(base)
    rng = random.Random(4)
    failures, refused = [], 0
    n = N_CASES if kind == "stepped-sine" else N_CASES // 2
    for case in range(n):
        path = tmp_path / f"case{case % 8}.h5"
        shutil.copyfile(base, path)
        with h5py.File(path, "r+") as f:
            what = "; ".join(_mutate_h5(f, rng) for _ in range(rng.choice((1, 1, 2))))
        try:
            data = read_measurement(path)
        except MeasurementFileError as exc:
            refused += 1
            if str(path) not in str(exc):
                failures.append(f"{what}: message does not name the file: {exc}")
            continue
        except Exception as exc:  # noqa: BLE001 - exactly what the fuzzer hunts
            failures.append(f"{what}: {type(exc).__name__}: {exc}")
            continue
        if "nan" in what or "inf" in what:
            for field in ("response", "force", "frequency_hz", "levels_n", "h1", "coherence"):
                value = getattr(data, field, None)
                if isinstance(value, np.ndarray) and not np.all(np.isfinite(value)):
                    failures.append(f"{what}: a non-finite {field} was accepted")
    assert not failures, f"{len(failures)} failures, e.g.\n" + "\n".join(failures[:15])
    assert refused > n // 4, refused


def test_fuzzed_base_documents_round_trip():
    """The unmutated documents load and round-trip (the fuzzers' starting points are valid)."""
    _model_round_trip(Model.from_toml_text(MODEL_TEXT), "base")
    for name, path in builtin_plans().items():
        _plan_round_trip(plan_from_dict(tomllib.loads(path.read_text()), name), name)
    _setup_round_trip(
        setup_from_dict(tomllib.loads(builtin_setups()["reference"].read_text())), "s"
    )
