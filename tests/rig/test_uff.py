"""UFF 58 export of a measurement file's FRFs, read back with pyuff."""

import numpy as np
import pytest
import pyuff

from analysis.measurement_file import (
    RandomFRF,
    StepRecord,
    create_stepped_sine,
    write_random,
)
from rig.config.setup import load_setup
from rig.export.uff import export_uff

SETUP = load_setup("reference")
CHANNELS = SETUP.channels_for_points([3, 6, 7])


def _stepped_file(path, steps=True):
    rng = np.random.default_rng(1)
    infos = [c.channel_info() for c in CHANNELS]
    levels = [2.0, 8.0]
    targets = np.array([[lv, 0.02 * lv, 0.02 * lv] for lv in levels], dtype=complex)
    with create_stepped_sine(
        path,
        channels=infos,
        actuator=SETUP.actuator,
        levels_n=levels,
        orders_num=[1, 2, 3],
        orders_den=[1, 1, 1],
        force_targets=targets,
        config={"plan": {"name": "unit"}},
        setup=SETUP.to_dict(),
    ) as w:
        if steps:
            index = 0
            for li in range(2):
                for f in (24.0, 22.0, 23.0):  # measured out of frequency order
                    force = targets[li] * (1 + 0.01j)
                    resp = rng.standard_normal((4, 3)) + 1j * rng.standard_normal((4, 3))
                    resp[0] = force
                    w.append_step(
                        StepRecord(
                            plan_index=index,
                            level_index=li,
                            sweep_direction=1,
                            frequency_target_hz=f,
                            frequency_hz=f + 0.01,
                            force=force,
                            force_std=np.full(3, 1e-3),
                            response=resp,
                            response_std=np.full((4, 3), 1e-3),
                            drive=np.full(3, 0.1 + 0j),
                            n_blocks=16,
                            control_iterations=2,
                            control_converged=True,
                            control_error=0.001,
                        )
                    )
                    index += 1
        w.finish("success" if steps else "aborted", "")
    return path


def test_stepped_sine_export_round_trip(tmp_path):
    path = _stepped_file(tmp_path / "run.h5")
    n = export_uff(path, tmp_path / "run.uff")
    assert n == 2 * 3 * 3  # levels x orders x (channels - drive force)
    sets = pyuff.UFF(str(tmp_path / "run.uff")).read_sets()
    assert len(sets) == n
    from analysis.measurement_file import read_measurement

    data = read_measurement(path)
    by_key = {(s["load_case_id"], s["ver_num"], s["rsp_ent_name"]): s for s in sets}
    for li in range(2):
        part = data.select(level_index=li)
        order = np.argsort(part.frequency_hz)
        for k in range(3):
            for name in ("acc3", "acc6", "acc7"):
                s = by_key[(li + 1, k + 1, name)]
                assert s["func_type"] == 4 and s["abscissa_spacing"] == 0
                assert np.allclose(s["x"], part.frequency_hz[order])
                assert np.allclose(s["data"], part.frf(name)[order, k], rtol=1e-6)
                ch = next(c for c in CHANNELS if c.name == name)
                assert (s["rsp_node"], s["rsp_dir"], s["ref_node"], s["ref_dir"]) == (
                    ch.point,
                    2,
                    3,
                    2,
                )
                assert f"H^{k + 1} {name}/force3" in s["id1"]
                assert f"level {data.levels_n[li]:g} N, sweep up" in s["id2"]


def test_random_export(tmp_path):
    chans = SETUP.channels_for_points(range(1, 14))
    f = np.arange(10.0, 20.0, 0.5)
    h1 = np.ones((f.size, len(chans)), dtype=complex) * (2 + 1j)
    h1[:, 0] = 1.0
    frf = RandomFRF(f, h1, np.ones(h1.shape), np.full(f.size, 1e-3), 8, "boxcar", 0.0, 2560.0, 0.3)
    path = write_random(
        tmp_path / "lin.h5",
        channels=[c.channel_info() for c in chans],
        actuator=SETUP.actuator,
        frf=frf,
        config={"plan": {"name": "linear"}},
        setup=SETUP.to_dict(),
    )
    assert export_uff(path, tmp_path / "lin.uff") == len(chans) - 1
    sets = pyuff.UFF(str(tmp_path / "lin.uff")).read_sets()
    assert [s["rsp_node"] for s in sets] == [c.point for c in chans[1:]]
    post = next(s for s in sets if s["rsp_node"] == 8)
    assert post["rsp_dir"] == 1  # the posts measure x
    assert np.allclose(post["x"], f) and np.allclose(post["data"], 2 + 1j)
    assert post["abscissa_spacing"] == 1 and post["id1"].startswith("H1 acc8/force3")


def test_export_refuses_to_overwrite_and_empty_files(tmp_path):
    path = _stepped_file(tmp_path / "run.h5")
    export_uff(path, tmp_path / "out.uff")
    with pytest.raises(FileExistsError, match="--overwrite"):
        export_uff(path, tmp_path / "out.uff")
    assert export_uff(path, tmp_path / "out.uff", overwrite=True) == 18
    empty = _stepped_file(tmp_path / "empty.h5", steps=False)
    with pytest.raises(ValueError, match="no completed step"):
        export_uff(empty, tmp_path / "empty.uff")
    assert not (tmp_path / "empty.uff").exists()
