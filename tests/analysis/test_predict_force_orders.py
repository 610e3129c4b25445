"""A model driven by every force the shaker exerts, the file's extra force orders included.

Where the tip strikes the stop the response carries harmonics, and the shaker (armature mass,
suspension, stinger) resists them: the force gauge measures a force at orders the drive does
not contain. The reference is the simulated rig's balance of the coupled shaker and structure
(:class:`sim_backend.rig_model.RigModel`, 20 harmonics), which shares no code path with the
analysis' predictor beyond the structure's matrices.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.measurement_file import (
    Actuator,
    ChannelInfo,
    StepRecord,
    create_stepped_sine,
    read_measurement,
)
from analysis.predict import SteppedSinePredictor
from analysis.predict_branches import BranchMatchedPredictor
from sim_backend.rig_model import RigModel, SensorSpec
from sim_backend.truth import load_truth

SENSORS = (
    SensorSpec("force", 3, "y", 0.01),
    SensorSpec("acceleration", 3, "y", 0.0),
    SensorSpec("acceleration", 6, "y", 0.0055),
    SensorSpec("acceleration", 7, "y", 0.0055),
)
NAMES = ("force3", "acc3", "acc6", "acc7")
ORDERS = 3
EXTRA = 5  # orders 4-8
FREQUENCIES_HZ = np.arange(25.0, 26.61, 0.4)  # up through the contact resonance at about 6 N


@pytest.fixture(scope="module")
def rig_steps() -> tuple[np.ndarray, np.ndarray]:
    """Noise-free phasors of a constant-voltage sweep up: force (n, 8), channels (n, 4, 3)."""
    rig = RigModel(load_truth("reference"), SENSORS, drive_point=3)
    cols = [rig.sensor_output(s) for s in SENSORS]
    u = 1.2 * np.array([1.0, 0.02, 0.02])
    force, resp, prev = [], [], None
    for f in FREQUENCIES_HZ:
        w = 2 * np.pi * f
        st = rig.steady_state(w, u, prev)
        assert st.converged
        prev = st
        k = np.arange(1, ORDERS + EXTRA + 1)
        ph = np.empty((len(SENSORS), k.size), complex)
        for i, (s, (col, sign)) in enumerate(zip(SENSORS, cols, strict=True)):
            factor = 1.0 if s.quantity == "force" else -((k * w) ** 2)
            ph[i] = sign * factor * st.outputs[k, col]
        force.append(ph[0])
        resp.append(ph[:, :ORDERS])
    return np.array(force), np.array(resp)


def _file(path: Path, force: np.ndarray, resp: np.ndarray, extra: bool) -> Path:
    truth = load_truth("reference")
    s = truth.shaker
    static = 1.0 / (1.0 / s.suspension_stiffness_n_per_m + 1.0 / s.stinger_stiffness_n_per_m)
    channels = [
        ChannelInfo(
            name=n,
            point=sp.point,
            direction="y",
            quantity=sp.quantity,
            unit="N" if sp.quantity == "force" else "m/s^2",
            sensitivity=1.0,
            sensitivity_unit="mV/N" if sp.quantity == "force" else "mV/g",
            role="drive-force" if n == "force3" else "response",
            mass_kg=sp.mass_kg,
        )
        for n, sp in zip(NAMES, SENSORS, strict=True)
    ]
    kwargs = {}
    if extra:
        kwargs = {"extra_orders_num": list(range(4, 9)), "extra_orders_den": [1] * EXTRA}
    with create_stepped_sine(
        path,
        channels=channels,
        actuator=Actuator(3, "y", static),
        levels_n=[6.0],
        orders_num=[1, 2, 3],
        orders_den=[1, 1, 1],
        force_targets=[[6.0, 0.12, 0.12]],
        config={},
        setup={},
        **kwargs,
    ) as w:
        for i, f in enumerate(FREQUENCIES_HZ):
            std = 1e-6 * np.abs(resp[i]) + 1e-12
            w.append_step(
                StepRecord(
                    plan_index=i,
                    level_index=0,
                    sweep_direction=1,
                    frequency_target_hz=f,
                    frequency_hz=f,
                    force=resp[i, 0],
                    force_std=std[0],
                    response=resp[i],
                    response_std=std,
                    drive=np.zeros(ORDERS, complex),
                    n_blocks=48,
                    control_iterations=1,
                    control_converged=True,
                    control_error=0.0,
                    extra_force=force[i, ORDERS:] if extra else None,
                    extra_force_std=np.full(EXTRA, 1e-9) if extra else None,
                )
            )
        w.finish("success")
    return path


def test_a_model_driven_by_the_extra_force_orders_matches_the_coupled_rig(
    tmp_path: Path, rig_steps
) -> None:
    force, resp = rig_steps
    # the effect: in contact the shaker pushes back at orders 4-8 by several per cent
    push = np.abs(force[:, ORDERS:]).max(axis=1) / np.abs(force[:, 0])
    assert push.max() > 0.02

    model = load_truth("reference").model  # the truth's own parameters: only the drive differs
    errors = {}
    for extra in (True, False):
        data = read_measurement(_file(tmp_path / f"e{extra}.h5", force, resp, extra))
        assert data.extra_orders == (tuple(range(4, 9)) if extra else ())
        for cls in (SteppedSinePredictor, BranchMatchedPredictor):
            pred = cls(model, data)
            H, _ = pred.measured()
            got = pred.predict().frf
            assert got.shape == H.shape
            # misfit relative to each channel's fundamental FRF, per step
            rel = np.abs(got - H) / np.abs(H[:, :, :1])
            errors[extra, cls.__name__] = float(rel.max())
    # with every measured force the analysis reproduces the rig to its harmonic truncation
    # (9 against 20 harmonics); with orders 1-3 alone it misses by per cents of the fundamental
    assert errors[True, "SteppedSinePredictor"] < 2e-3, errors
    assert errors[True, "BranchMatchedPredictor"] < 2e-3, errors
    assert errors[False, "SteppedSinePredictor"] > 10 * errors[True, "SteppedSinePredictor"]
    assert errors[False, "SteppedSinePredictor"] > 1e-2, errors
