"""Compare and localise: block verdicts with their numbers, recorded orders held at zero,
standard errors carried through the model, steps the rig did not converge at."""

from __future__ import annotations

import numpy as np

from analysis.diagnosis import BranchMatchedPredictor, compare
from analysis.measurement_file import (
    StepRecord,
    create_stepped_sine,
    read_measurement,
)


def test_blocks_say_where_the_model_fails(runs, reference_model) -> None:
    good = compare(reference_model, runs("reference"))
    assert good.adequate and not good.failing()
    assert "consistent with the noise" in good.blocks[0].verdict
    bad = compare(reference_model, runs("damper_p5"))
    worst = bad.failing()[0]
    # a damper acts where the beam moves most: at the resonance, at the highest level
    assert worst.level_n == 8.0 and worst.band_hz[0] <= 28.0
    assert "fails here" in worst.verdict and "p = " in worst.verdict
    grid, levels = bad.map_sensor_order_level()
    assert grid.shape == (3, 3, len(levels)) and np.nanmax(grid) > 100


def _held_file(path, model_run, reference_model):
    """The reference run rewritten with an order 4 held at zero force (from the model)."""
    src = model_run
    pred = BranchMatchedPredictor(reference_model, src)
    pb, points = pred.solve(rows=np.arange(src.n_steps))
    targets = np.concatenate([src.force_targets, np.zeros((src.force_targets.shape[0], 1))], 1)
    w = create_stepped_sine(
        path,
        channels=list(src.channels),
        actuator=src.actuator,
        levels_n=list(src.levels_n),
        orders_num=[1, 2, 3, 4],
        orders_den=[1, 1, 1, 1],
        force_targets=targets,
        config={},
        setup={},
        overwrite=True,
    )
    rng = np.random.default_rng(0)
    with w:
        for i in range(src.n_steps):
            f4 = 0.01 * (rng.standard_normal() + 1j * rng.standard_normal())
            force = np.append(src.force[i], f4)
            resp = np.concatenate([src.response[i], np.zeros((src.response.shape[1], 1))], 1)
            resp[0, 3] = f4
            std = np.concatenate([src.response_std[i], src.response_std[i][:, 2:3]], 1)
            w.append_step(
                StepRecord(
                    plan_index=i,
                    level_index=int(src.level_index[i]),
                    sweep_direction=1,
                    frequency_target_hz=float(src.frequency_hz[i]),
                    frequency_hz=float(src.frequency_hz[i]),
                    force=force,
                    force_std=std[0],
                    response=resp,
                    response_std=std,
                    drive=np.append(src.drive[i], 0),
                    n_blocks=48,
                    control_iterations=2,
                    control_converged=i != 5,
                    control_error=0.0,
                )
            )
        w.finish("success", "")
    return read_measurement(path)


def test_held_orders_drive_the_model_but_are_not_compared(runs, reference_model, tmp_path) -> None:
    data = _held_file(tmp_path / "held.h5", runs("reference"), reference_model)
    pred = BranchMatchedPredictor(reference_model, data)
    assert list(pred.compared) == [0, 1, 2] and len(data.orders) == 4
    cmp = compare(reference_model, data, predictor=pred)
    assert cmp.orders == ["1", "2", "3"] and cmp.residual.shape[2] == 3
    # the step flagged as not converged under force control is left out of the figures
    assert cmp.left_out.tolist() == [5] and np.all(np.isnan(cmp.residual[5]))


def test_standard_errors_through_the_model(runs, reference_model) -> None:
    data = runs("reference")
    pred = BranchMatchedPredictor(reference_model, data)
    _, file_sigma = pred.measured()
    p, sigma = pred.predict_with_sigma()
    linear = data.frequency_hz < 23.5  # below the resonance the stop stays open
    ratio = sigma[linear, :, 0] / file_sigma[linear, :, 0]
    # where the structure is linear the model's tangent is the receptance: the file's value
    assert np.allclose(ratio, 1.0, rtol=0.02)
    assert np.all(sigma > 0) and np.all(np.isfinite(sigma))


def test_compare_scores_with_the_standard_errors_through_the_model(runs, reference_model) -> None:
    data = runs("reference")
    pred = BranchMatchedPredictor(reference_model, data)
    H, file_sigma = pred.measured()
    p, sigma = pred.predict_with_sigma()
    by_default = compare(reference_model, data, predictor=pred)
    ok = ~np.isin(np.arange(data.n_steps), by_default.left_out)
    # the default divides by the model's standard errors (those a calibration fits with; at
    # least the file's smallest) ...
    floor = file_sigma[np.isfinite(file_sigma) & (file_sigma > 0)].min()
    expected = (p.frf - H) / np.maximum(sigma, floor)
    assert np.allclose(by_default.residual[ok], expected[ok], rtol=1e-9)
    # ... and differs from the file's first-order errors where the contact acts
    by_file = compare(reference_model, data, predictor=pred, sigma="file")
    assert np.allclose(by_file.residual[ok], ((p.frf - H) / file_sigma)[ok], rtol=1e-9)
    assert not np.allclose(by_default.residual[ok], by_file.residual[ok], rtol=1e-3)


def test_an_uncalibrated_model_is_named_as_such(runs, reference_model, capsys) -> None:
    """The shipped model, every calibrated parameter at its nominal value, is not calibrated."""
    import argparse

    from analysis.diagnosis.cli import add_parsers
    from analysis.diagnosis.compare import uncalibrated_note
    from analysis.model import load_model

    shipped = load_model()
    note = uncalibrated_note(shipped)
    assert note and "not been calibrated yet" in note
    assert "calibrate-linear" in note and "python -m analysis calibrate " in note
    assert uncalibrated_note(reference_model) is None  # a calibrated one: no note
    name = shipped.parameter_names(calibrate=True)[0]
    nudged = shipped.with_values({name: shipped.parameters[name].nominal * 1.01})
    assert uncalibrated_note(nudged) is None
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["compare", str(runs("reference").path)])
    out = args.func(args)
    assert out["notes"] == [note]
    assert f"note: {note}" in capsys.readouterr().out
    assert compare(reference_model, runs("reference")).notes == []
