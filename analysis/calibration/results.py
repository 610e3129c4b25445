"""Result files of the calibration commands: JSON results and calibrated model files.

Every command writes a new model file with the calibrated values (the input file is kept) and a
JSON result (parameters, covariance, history, settings), so a later command (cross-validation,
validation, report) continues from the files alone.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from analysis.calibration.lhs import Distribution
from analysis.calibration.lm import LeastSquaresResult
from analysis.calibration.nonlinear import CalibrationSettings, NonlinearCalibration
from analysis.calibration.parameters import ParameterSpace
from analysis.calibration.uncertainty import HeldParameters
from analysis.model import Model

__all__ = ["load_calibration", "save_calibration"]


def save_calibration(
    result: NonlinearCalibration, model: Model, out_dir: str | Path, data_path: str | Path
) -> dict[str, Path]:
    """Write ``calibration.json`` and ``calibrated_model.toml`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = result.to_json()
    doc["measurement_file"] = str(Path(data_path).resolve())
    doc["model_source"] = str(model.source)
    doc["model_toml"] = model.to_toml()
    doc["units"] = {n: model.parameters[n].unit for n in result.space.names}
    json_path = out / "calibration.json"
    json_path.write_text(json.dumps(doc, indent=1))
    model_path = result.calibrated_model(model).save(out / "calibrated_model.toml")
    return {"result": json_path, "model": Path(model_path)}


def load_calibration(path: str | Path) -> tuple[NonlinearCalibration, Model, str]:
    """Read a ``calibration.json``: the result, the model it started from, the data path."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
        model = Model.from_toml_text(doc["model_toml"], source=doc.get("model_source", str(path)))
        names = tuple(doc["names"])
    except (OSError, ValueError, KeyError) as exc:
        raise ValueError(f"{path}: not a calibration result ({exc})") from None
    s = dict(doc["settings"])
    dists = s.pop("distributions", None)
    for k in ("parameters", "calibration_levels_n", "channels"):
        if s.get(k) is not None:
            s[k] = tuple(s[k])
    settings = CalibrationSettings(
        **s,
        distributions=None if dists is None else {k: Distribution(**v) for k, v in dists.items()},
    )
    space = ParameterSpace.from_model(model, names)
    p = np.array([doc["parameters"][n] for n in names])
    x = space.to_theta(p)
    lm = LeastSquaresResult(
        x,
        doc["lm"]["cost"],
        np.zeros(0),
        np.zeros((0, len(names))),
        np.eye(len(names)),
        doc["lm"]["nfev"],
        0,
        doc["lm"]["nit"],
        doc["lm"]["success"],
        doc["lm"]["message"],
        [{k: v for k, v in h.items() if k != "parameters"} for h in doc["lm"]["history"]],
    )
    res = NonlinearCalibration(
        parameters=dict(doc["parameters"]),
        cov=np.array(doc["cov"]),
        chi2_per_dof=doc["chi2_per_dof"],
        n_residuals=doc["n_residuals"],
        starts=np.array(doc["starts"]),
        start_costs=np.array([np.inf if c is None else c for c in doc["start_costs"]]),
        start_exact=(
            None
            if doc.get("start_cost_exact") is None  # written before starts could be stopped
            else np.array(doc["start_cost_exact"], bool)
        ),
        lm=lm,
        space=space,
        settings=settings,
        calibration_levels_n=tuple(doc["calibration_levels_n"]),
        validation_level_n=doc["validation_level_n"],
        timings=doc.get("timings", {}),
    )
    unc = doc.get("uncertainty")
    if unc is not None:  # results written before the uncertainty record hold cov alone
        res.cov_noise = np.array(doc["cov_noise"], dtype=float)
        res.held = None if unc.get("held") is None else HeldParameters.from_json(unc["held"])
        res.held_cov = np.array(unc["held_cov"], dtype=float)
        res.held_gain = None if unc.get("held_gain") is None else np.array(unc["held_gain"])
        res.noise_scale = np.array(unc["noise_scale"], dtype=float)
        ratio = unc.get("fold_ratio")
        res.fold_ratio = None if ratio is None else np.array(ratio, dtype=float)
        res.fold_misfit = list(doc.get("fold_misfit", []))
        res.held_posterior = unc.get("held_posterior")
        if unc.get("joint_names") is not None:
            res.joint_names = tuple(unc["joint_names"])
            res.cov_joint = np.array(unc["cov_joint"], dtype=float)
        res.combine()
    return res, model, doc.get("measurement_file", "")
