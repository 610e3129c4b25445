"""Reduced simulated runs of the shipped truths for the diagnosis tests.

The stepped sine is the truth's forced response (:func:`benchmarks.diagnose.simulate_stepped_sine`)
on a reduced grid (2, 5 and 8 N; 22-38 Hz with 0.25 Hz steps around the resonance) at 12
harmonics and 256 samples; the model under test is the reference truth's structure and
contact (what a perfect calibration of the paper's kind gives), so each test starts where a
diagnosis starts: a calibrated model that misses the hidden effect.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

import sim_backend.hysteresis  # noqa: F401  (the hysteretic truth's element)
from analysis.measurement_file import read_measurement
from analysis.model import Model
from analysis.model_file import parse_document
from benchmarks.diagnose import simulate_linear_test, simulate_stepped_sine
from sim_backend.truth import TRUTH_DIR

LEVELS_N = (2.0, 5.0, 8.0)
FREQUENCIES_HZ = np.unique(
    np.round(
        np.concatenate(
            [[22.0, 23.0, 24.0], np.arange(24.5, 28.01, 0.25), [29.0, 31.0, 34.0, 38.0]]
        ),
        6,
    )
)


def truth_as_model(name: str) -> Model:
    """A truth's model file without its [truth] table (an analysis model)."""
    path = TRUTH_DIR / f"{name}.toml"
    doc = tomllib.loads(path.read_text())
    doc.pop("truth")
    return Model(**parse_document(doc, str(path)))


@pytest.fixture(scope="session")
def reference_model() -> Model:
    """The rig as calibrated: Table 2's linear values, the paper's contact, the damping."""
    return truth_as_model("reference")


@pytest.fixture(scope="session")
def runs(tmp_path_factory: pytest.TempPathFactory):
    """``runs(name)``: the reduced stepped-sine file of a truth (cached per session)."""
    folder = tmp_path_factory.mktemp("diagnosis-runs")
    cache: dict[str, Path] = {}

    def get(name: str, linear: bool = False):
        key = name + (":linear" if linear else "")
        if key not in cache:
            if linear:
                cache[key] = simulate_linear_test(name, folder / f"{name}_linear.h5", seed=3)
            else:
                cache[key] = simulate_stepped_sine(
                    name,
                    folder / f"{name}.h5",
                    levels_n=LEVELS_N,
                    frequencies_hz=FREQUENCIES_HZ,
                    n_harmonics=12,
                    n_time=256,
                    seed=3,
                )
        return cache[key] if linear else read_measurement(cache[key])

    return get
