"""Synthetic runs and their calibrations, shared by the tests of this package."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.calibration.linear import LinearCalibration, calibrate_linear
from analysis.model import load_model
from tests.analysis.calibration_linear.synthetic import write_rig_run

NOISE = 0.02
"""Relative standard deviation of the complex Gaussian noise of the noisy run."""


@pytest.fixture(scope="session")
def clean_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_rig_run(tmp_path_factory.mktemp("linear") / "clean.h5")


@pytest.fixture(scope="session")
def noisy_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_rig_run(tmp_path_factory.mktemp("linear") / "noisy.h5", noise=NOISE, seed=7)


@pytest.fixture(scope="session")
def clean_result(clean_run: Path) -> LinearCalibration:
    return calibrate_linear(load_model(), clean_run)


@pytest.fixture(scope="session")
def noisy_result(noisy_run: Path) -> LinearCalibration:
    return calibrate_linear(load_model(), noisy_run)
