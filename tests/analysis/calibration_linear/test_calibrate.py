"""Linear calibration end to end on synthetic runs of the reference rig with known truth.

Truth: Table 2's calibrated values, 5.5 g sensors at the 13 points, modal damping
``TRUE_ZETA``; start: the model file's nominal values. Tolerances: 0.5 % on the parameters and
1 % on the damping without noise, 2 % and 10 % with 2 % complex noise.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from analysis.calibration.linear import (
    CalibrationError,
    LinearCalibrationSettings,
    calibrate_linear,
    sensor_masses,
)
from analysis.linear.modal import modal_analysis
from analysis.measurement_file import ChannelInfo, RandomFRF, read_measurement, write_random
from analysis.model import load_model
from tests.analysis import measurement_samples as ms
from tests.analysis.calibration_linear.synthetic import (
    SENSOR_MASS_KG,
    TRUE_VALUES,
    TRUE_ZETA,
    write_rig_run,
)


def _errors(result) -> dict[str, float]:
    return {n: abs(result.parameters[n] / TRUE_VALUES[n] - 1) for n in result.names}


def test_recovers_parameters_without_noise(clean_result) -> None:
    assert clean_result.success
    assert clean_result.names == ("E_frame", "E_corner", "E_beam", "rho_corner", "k_mount")
    assert max(_errors(clean_result).values()) < 5e-3, _errors(clean_result)


@pytest.mark.slow
def test_recovers_parameters_with_noise(noisy_result) -> None:
    assert noisy_result.success
    assert max(_errors(noisy_result).values()) < 0.02, _errors(noisy_result)


@pytest.mark.parametrize(
    "which, tol",
    [("clean_result", 0.01), pytest.param("noisy_result", 0.10, marks=pytest.mark.slow)],
)
def test_identified_damping_in_the_model(which: str, tol: float, request) -> None:
    result = request.getfixturevalue(which)
    per_mode = result.model.damping.per_mode
    assert sorted(per_mode) == sorted(TRUE_ZETA)
    for mode, zeta in TRUE_ZETA.items():
        assert per_mode[mode] == pytest.approx(zeta, rel=tol)
    assert all(m.mac > 0.99 for m in result.modes)
    assert result.model.damping.default_zeta == load_model().damping.default_zeta


@pytest.mark.slow  # the noisy calibration fixture takes 14 s
def test_split_and_validation_improves(noisy_result) -> None:
    r = noisy_result
    assert r.calibration_points == (1, 2, 3, 4, 5, 6, 7, 8, 11)
    assert r.validation_points == (9, 10, 12, 13)
    assert len(r.calibration_channels) == 9 and len(r.validation_channels) == 4
    before, after = r.validation["before"], r.validation["after"]
    for key in ("equalized", "measured"):
        assert after[key]["validation"] < 0.1 * before[key]["validation"]
        assert after[key]["calibration"] < 0.1 * before[key]["calibration"]
    # with the identified damping the model meets the measured FRFs to about the noise
    assert after["measured"]["validation"] < 2 * np.log10(1.02)


@pytest.mark.slow  # the noisy calibration fixture takes 14 s
def test_covariance_and_correlation(noisy_result) -> None:
    r = noisy_result
    n = len(r.names)
    assert r.cov.shape == (n, n) and np.allclose(r.cov, r.cov.T)
    assert np.all(np.linalg.eigvalsh(r.cov) > 0)
    np.testing.assert_allclose(np.diag(r.correlation), 1.0)
    for name in r.names:
        assert 0 < r.std[name] < 0.01 * r.parameters[name]
    assert r.jac.shape == (r.metric_frequency_hz.size * 9, n)
    # the damping continuation, then the fit under the model file's priors at zeta0 (MAP)
    assert [s["zeta0"] for s in r.stages] == [0.2, 0.1, 0.05, 0.02, r.zeta0, r.zeta0]
    assert [bool(s.get("prior")) for s in r.stages] == [False] * 5 + [True]


def test_sensor_masses_from_the_channel_table(clean_run) -> None:
    masses = sensor_masses(read_measurement(clean_run))
    # the impedance head's force and acceleration channels share a serial: counted once
    assert masses == {p: pytest.approx(SENSOR_MASS_KG) for p in range(1, 14)}


def test_model_file_written_new_and_reloads(clean_result, tmp_path: Path) -> None:
    path = clean_result.save_model(tmp_path / "calibrated.toml")
    reloaded = load_model(path)
    for n in clean_result.names:
        assert reloaded.parameters[n].value == pytest.approx(clean_result.parameters[n])
    assert reloaded.damping == clean_result.model.damping
    assert "sensors" not in {m.group for m in reloaded.frame.masses}  # the structure only
    assert load_model().parameters["E_corner"].value == 150e9  # the input file is untouched
    doc = json.loads(json.dumps(clean_result.to_json()))
    assert doc["parameters"] == clean_result.parameters
    assert len(doc["identified_modes"]["modes"]) == 7
    assert doc["damping_per_mode"]["5"] == pytest.approx(TRUE_ZETA[5], rel=0.01)


@pytest.mark.slow  # the noisy calibration fixture takes 14 s
def test_a_test_that_determines_everything_says_nothing(noisy_result) -> None:
    assert noisy_result.undetermined() == {}
    assert noisy_result.unidentified_modes == []
    assert noisy_result.identifiability_notes() == []


@pytest.mark.slow
def test_parameters_the_test_leaves_undetermined_are_named(tmp_path: Path) -> None:
    """4 % damping on the three mount modes (10.8, 11.2 and 15 Hz) merges them into one test
    mode: rho_corner, which acts mostly on them, is undetermined, and the two model modes
    without a test partner are reported with d ln f / d ln p, checked here against central
    differences of the modal analysis (relative step 1e-3: smaller steps meet the round-off
    of the low mount modes; tolerance 1e-3 absolute)."""
    zeta = {**TRUE_ZETA, 1: 0.04, 2: 0.04, 3: 0.04}
    run = write_rig_run(tmp_path / "merged.h5", noise=0.05, seed=3, zeta=zeta)
    result = calibrate_linear(load_model(), run)
    bad = result.undetermined()
    assert "rho_corner" in bad and bad["rho_corner"] > 0.05
    assert "E_beam" not in bad and "k_mount" not in bad
    missing = result.unidentified_modes
    assert [m["model_mode"] for m in missing] == [1, 3]
    notes = "\n".join(result.identifiability_notes())
    assert "rho_corner" in notes and f"{missing[1]['frequency_hz']:.2f} Hz" in notes
    masses = sensor_masses(read_measurement(run))
    loaded = result.model.add_masses(masses)  # the model the sensitivities are of
    for name in ("rho_corner", "k_mount"):
        p = loaded.parameters[name].value
        f = []
        for step in (1e-3, -1e-3):
            asm = loaded.with_values({name: p * (1 + step)}).assemble()
            f.append(modal_analysis(asm.M, asm.K).frequency_hz)
        fd = (np.log(f[0]) - np.log(f[1])) / (np.log1p(1e-3) - np.log1p(-1e-3))
        for m in missing:
            assert m["sensitivity"][name] == pytest.approx(fd[m["model_mode"] - 1], abs=1e-3)
    doc = json.loads(json.dumps(result.to_json()))
    assert doc["undetermined"] == pytest.approx(bad)
    assert len(doc["unidentified_modes"]) == 2
    # not just named: held at the nominal value with the prior's uncertainty, and said why
    assert result.status["rho_corner"] == "held" and doc["status"]["rho_corner"] == "held"
    assert result.parameters["rho_corner"] == load_model().parameters["rho_corner"].nominal
    prior = load_model().parameters["rho_corner"].prior_rel_std
    assert result.std["rho_corner"] == pytest.approx(prior * result.parameters["rho_corner"])
    assert "held at its nominal 4000 kg/m^3" in doc["status_reason"]["rho_corner"]
    assert "held at its nominal value: rho_corner" in notes


@pytest.mark.slow
def test_a_parameter_that_runs_to_a_bound_is_held_not_passed_on(tmp_path: Path) -> None:
    """A frame stiffer than the model's range allows (E_frame 340 GPa, upper bound 300, as a
    file from a rig whose frame differs from the model's would ask): the fit runs E_frame to
    its bound; it is reported as such and held at its nominal value with its prior, the
    calibrated model file does not carry the bound value, and the others are fitted with it
    held and its uncertainty carried into theirs."""
    run = write_rig_run(
        tmp_path / "stiff.h5", noise=0.02, seed=4, values={**TRUE_VALUES, "E_frame": 340e9}
    )
    nominal = load_model()
    result = calibrate_linear(nominal, run)
    assert result.status["E_frame"] == "held"
    assert "upper bound 3e+11 Pa" in result.status_reason["E_frame"]
    assert result.parameters["E_frame"] == nominal.parameters["E_frame"].nominal
    assert result.model.parameters["E_frame"].value == nominal.parameters["E_frame"].nominal
    assert all(result.status[n] == "fitted" for n in ("E_beam", "k_mount"))
    prior = nominal.parameters["E_frame"].prior_rel_std
    assert result.std["E_frame"] == pytest.approx(prior * result.parameters["E_frame"])
    # the held value's uncertainty reaches the fitted ones: correlated with it
    i, j = result.names.index("E_frame"), result.names.index("E_beam")
    assert result.cov[i, j] != 0.0


def test_trf_from_a_far_start(clean_run) -> None:
    """The damping continuation brings trf from E_beam 19 % and E_frame 27 % off."""
    start = load_model().with_values({"E_frame": 150e9, "E_beam": 240e9})
    result = calibrate_linear(start, clean_run, method="trf")
    assert max(_errors(result).values()) < 5e-3, _errors(result)


def test_information_split_and_kept_sensors(clean_run) -> None:
    settings = LinearCalibrationSettings(calibration_points="information", keep_sensor_masses=True)
    result = calibrate_linear(load_model(), clean_run, settings)
    assert len(result.calibration_points) == 9 and len(result.validation_points) == 4
    assert set(result.calibration_points).isdisjoint(result.validation_points)
    assert max(_errors(result).values()) < 5e-3
    report = result.model.assemble().mass_report()
    assert report["sensors"] == pytest.approx(13 * SENSOR_MASS_KG)


# -- errors --------------------------------------------------------------------------------
def test_rejects_a_stepped_sine_file(tmp_path: Path) -> None:
    path = ms.write_sample_stepped_sine(tmp_path / "stepped.h5")
    with pytest.raises(CalibrationError, match="random"):
        calibrate_linear(load_model(), path)


def test_rejects_a_channel_at_an_unknown_point(clean_run, tmp_path: Path) -> None:
    data = read_measurement(clean_run)
    extra = ChannelInfo(
        "acc14", 14, "y", "acceleration", "m/s^2", 10.0, "mV/g", "response", 0.0055, "A14"
    )
    frf = RandomFRF(
        frequency_hz=data.frequency_hz,
        h1=np.column_stack([data.h1, data.h1[:, -1]]),
        coherence=np.column_stack([data.coherence, data.coherence[:, -1]]),
        force_psd=data.force_psd,
        n_averages=data.n_averages,
        window=data.window,
        overlap=data.overlap,
        fs_hz=data.fs_hz,
        rms_force_n=data.rms_force_n,
    )
    path = write_random(
        tmp_path / "extra.h5",
        channels=[*data.channels, extra],
        actuator=data.actuator,
        frf=frf,
        config={},
        setup={},
    )
    with pytest.raises(CalibrationError, match="'acc14'.*no measurement point 14"):
        calibrate_linear(load_model(), path)


def test_rejects_too_few_modes_in_band(clean_run) -> None:
    with pytest.raises(CalibrationError, match="1 mode.*20-40 Hz.*at least 5"):
        calibrate_linear(load_model(), clean_run, band_hz=(20.0, 40.0))


def test_rejects_nonlinear_parameters(clean_run) -> None:
    with pytest.raises(CalibrationError, match="'k_c'.*group 'nonlinear'"):
        calibrate_linear(load_model(), clean_run, parameters=("E_beam", "k_c"))


@pytest.mark.parametrize(
    "change",
    [
        {"method": "simplex"},
        {"zeta0": 0.7},
        {"calibration_points": "best"},
        {"band_hz": (50.0, 10.0)},
        {"zeta0_schedule": (0.0,)},
    ],
)
def test_settings_are_validated(change: dict) -> None:
    with pytest.raises(ValueError):
        dataclasses.replace(LinearCalibrationSettings(), **change)
