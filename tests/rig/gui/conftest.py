"""Fixtures of the GUI tests: offscreen Qt, a recorded run, a model file, screenshots.

The tests drive the real windows with pytest-qt on the simulated rig (the ``quick`` plan at a
reduced sample rate) and save screenshots (see ``gui_helpers.SCREENSHOTS``).
"""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import dataclasses  # noqa: E402
import tomllib  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
import tomli_w  # noqa: E402

from rig.config.plans import FrequencyPlan, FrequencyRange, load_plan  # noqa: E402
from rig.config.setup import load_setup  # noqa: E402
from rig.run.session import TestRun, open_rig  # noqa: E402
from sim_backend.truth import TRUTH_DIR  # noqa: E402


@pytest.fixture(autouse=True)
def _qt_binding_works(qapp):
    """Fail (not skip) on a Qt binding that would crash the interpreter mid-test."""
    from rig.gui.qt_check import binding_problem
    from rig.gui.style import configure_app

    problem = binding_problem()
    if problem:
        pytest.fail(problem)
    configure_app(qapp)


@pytest.fixture(autouse=True)
def _runs_folder(tmp_path, monkeypatch) -> Path:
    """The GUI's new measurement files go to a temporary folder, not the user's home."""
    folder = tmp_path / "clearance-rig-runs"
    monkeypatch.setenv("CLEARANCE_RIG_RUNS", str(folder))
    return folder


@pytest.fixture(scope="session")
def lock_dir(tmp_path_factory) -> Path:
    """Device locks of these tests (apart from any other run on the machine)."""
    return tmp_path_factory.mktemp("locks")


@pytest.fixture(scope="session")
def damper_run(tmp_path_factory, lock_dir) -> Path:
    """A short run on the simulated rig whose truth hides a quadratic damper at point 5: the
    quick plan at 2, 5 and 8 N, 22-26 Hz (below the fold of the contact resonance, where the
    response can jump between branches)."""
    quick = load_plan("quick")
    plan = dataclasses.replace(
        quick,
        name="damper-check",
        excitation=dataclasses.replace(quick.excitation, levels_n=(2.0, 5.0, 8.0)),
        frequencies=FrequencyPlan((FrequencyRange(22.0, 26.0, 1.0),), "up"),
    )
    path = tmp_path_factory.mktemp("runs") / "damper_check.h5"
    setup = load_setup("reference").with_sample_rate(5120.0)
    options = {"truth": "damper_p5", "seed": 3, "sensor_masses_kg": setup.sensor_masses_kg()}
    with open_rig("sim", setup, backend_options=options, lock_dir=lock_dir) as rig:
        summary = TestRun(rig.backend, plan, setup, path).execute()
    assert summary.status == "success" and summary.n_done == 15
    return path


@pytest.fixture(scope="session")
def reference_model_file(tmp_path_factory) -> Path:
    """The rig as calibrated (the reference truth's structure and contact) as a model file."""
    doc = tomllib.loads((TRUTH_DIR / "reference.toml").read_text())
    doc.pop("truth")
    path = tmp_path_factory.mktemp("models") / "calibrated_rig.toml"
    path.write_text(tomli_w.dumps(doc))
    return path


@pytest.fixture(scope="session")
def calibration_file(tmp_path_factory, damper_run, reference_model_file) -> Path:
    """A calibration result of the damper run (a short one: 3 starts, 5 LM iterations)."""
    from analysis.calibration.nonlinear import CalibrationSettings, calibrate_nonlinear
    from analysis.calibration.results import save_calibration
    from analysis.measurement_file import read_measurement
    from analysis.model import load_model

    model = load_model(reference_model_file)
    settings = CalibrationSettings(n_starts=3, max_iterations=5, validation_level_n=0.0)
    result = calibrate_nonlinear(model, read_measurement(damper_run), settings)
    folder = tmp_path_factory.mktemp("calibration")
    return save_calibration(result, model, folder, damper_run)["result"]
