"""The diagnosis view on results built here: the read-out of a missing law under an unexplained
verdict (its words and its describing function against the amplitude, in the location's units)
and the places that move as a ranked candidate's."""

from __future__ import annotations

import html
import math
from types import SimpleNamespace

import numpy as np
import pyqtgraph as pg
import pytest

from analysis.diagnosis.candidates import Location
from analysis.diagnosis.readout import ForceReadout, describing_function, read_law
from rig.gui.diagnosis_view import DiagnosisView
from rig.gui.style import LogAxis
from tests.rig.gui.gui_helpers import make_window, screenshot

OMEGA = 2 * np.pi * 24.0  # rad/s
K_T, F_S = 1.0e5, 1.5  # N m/rad, N m: a joint that slips from 1.5e-5 rad
SAMPLES = 512


def _jenkins_first_harmonic(amplitudes: np.ndarray) -> np.ndarray:
    """First harmonic of a spring in series with a slider under ``x = A cos(wt)``, on its
    second period (the first settles the slider)."""
    theta = 2 * np.pi * (np.arange(SAMPLES) + 0.5) / SAMPLES
    out = []
    for a in amplitudes:
        x = a * np.cos(theta)
        z, f = 0.0, np.empty(SAMPLES)
        for _ in range(2):
            for i, xi in enumerate(x):
                fi = K_T * (xi - z)
                if abs(fi) > F_S:
                    z = xi - math.copysign(F_S / K_T, fi)
                    fi = math.copysign(F_S, fi)
                f[i] = fi
        out.append(2 / SAMPLES * np.sum(f * np.exp(-1j * theta)))
    return np.array(out)


def jenkins_readout(*, rotation: bool = True) -> ForceReadout:
    """A read-out of a stick-slip joint as a test at three force levels gives it: 8 steps per
    level, 2 % noise on the describing function, one step too small to be read."""
    rng = np.random.default_rng(4)
    amplitudes = np.geomspace(5e-6, 4e-4, 24)
    level = np.repeat([2.0, 5.0, 8.0], 8)
    omega = np.full(amplitudes.size, OMEGA)
    k_eq, c_eq = describing_function(amplitudes, _jenkins_first_harmonic(amplitudes), omega)
    scale = 0.02 * np.hypot(k_eq, omega * c_eq)
    sigma_k, sigma_c = scale, scale / omega
    k_eq = k_eq + sigma_k * rng.standard_normal(k_eq.size)
    c_eq = c_eq + sigma_c * rng.standard_normal(c_eq.size)
    seen = np.ones(amplitudes.size, bool)
    seen[0] = False
    reading = read_law(
        amplitudes[seen], omega[seen], k_eq[seen], c_eq[seen], sigma_k[seen], sigma_c[seen]
    )
    nan = np.full(amplitudes.size, np.nan)
    name = "joint clamp rz" if rotation else "point 12 y"
    return ForceReadout(
        name,
        name,
        "",
        rotation,
        0.0,
        amplitudes,
        omega,
        level,
        k_eq,
        c_eq,
        sigma_k,
        sigma_c,
        nan,
        nan,
        seen,
        reading,
    )


def _ranked(rank: int, group: int, label: str, location: Location) -> SimpleNamespace:
    return SimpleNamespace(
        rank=rank,
        group=group,
        candidate=SimpleNamespace(label=f"{label} at {location.name}", location=location),
        rms_over_noise=4.0 + rank,
        delta_bic=-100.0 / rank,
        verified=SimpleNamespace(parameters={"k": 1.0e3}),
    )


def diagnosis(verdict: str, readout=None, ranking=()) -> SimpleNamespace:
    """What the view reads of a :class:`analysis.diagnosis.Diagnosis`."""
    ranking = list(ranking)
    return SimpleNamespace(
        verdict=verdict,
        readout=readout,
        ranking=ranking,
        group=[r for r in ranking if r.group == 1] if verdict == "explained" else [],
        comparison=SimpleNamespace(rms_over_noise=12.0, chi2_per_dof=150.0),
        evidence=SimpleNamespace(findings=[]),
        screen=[],
        baseline=None,
        recommendation=None,
        settings=SimpleNamespace(tie_bic=10.0),
        timings={"total_s": 3.0},
    )


LOOK_ALIKE = Location(
    "point 12 y", alike=(Location("point 13 y"), Location("spring mount_right_y"))
)
ALONE = Location("point 5")


def _data_items(plot: pg.PlotWidget) -> list:
    return [i for i in plot.getPlotItem().listDataItems() if i.xData is not None and len(i.xData)]


def _axis_text(plot: pg.PlotWidget, side: str) -> str:
    return plot.getPlotItem().getAxis(side).labelText


@pytest.fixture(scope="module")
def joint_readout() -> ForceReadout:
    return jenkins_readout()


def test_an_unexplained_verdict_shows_its_readout_and_a_new_diagnosis_clears_it(
    qtbot, joint_readout
):
    assert joint_readout.kind == "stick_slip"  # the fixture reads as the law it is
    view = DiagnosisView()
    qtbot.addWidget(view)
    view.show()
    assert not view.readout_text.isVisible() and not view.readout_plots.isVisible()

    ranking = [_ranked(1, 1, "cubic_spring", Location("joint clamp rz"))]
    view.show_diagnosis(diagnosis("unexplained", joint_readout, ranking))
    assert view.readout_text.isVisible() and view.readout_plots.isVisible()
    shown = view.readout_text.text()
    assert html.escape(joint_readout.text) in shown and "sticks and slips" in shown
    for plot, unit in ((view.stiffness, "N m/rad"), (view.damping, "N m s/rad")):
        assert _axis_text(plot, "bottom") == "amplitude A [rad]"
        assert _axis_text(plot, "left").endswith(f"[{unit}]")
        items = _data_items(plot)
        # three levels' steps and the binned means; the step not read is left out
        assert sum(len(i.xData) for i in items) >= joint_readout.seen.sum()
        assert all(joint_readout.amplitude[0] not in i.xData for i in items)
        assert any(isinstance(i, pg.ErrorBarItem) for i in plot.getPlotItem().items)
    assert "2 N" in view.readout_legend.text() and "8 N" in view.readout_legend.text()
    seen = joint_readout.seen
    for plot, values in ((view.stiffness, joint_readout.k_eq), (view.damping, joint_readout.c_eq)):
        steps = [i for i in _data_items(plot) if i.opts["symbol"] == "o"]
        assert len(steps) == 3  # a colour per force level
        drawn = np.sort(np.concatenate([i.yData for i in steps]))
        np.testing.assert_array_equal(drawn, np.sort(values[seen]))
    # the damping's slope above the peak is resolved (drawn dashed), the stiffness's is not
    lines = [i for i in _data_items(view.damping) if i.opts["symbol"] is None]
    assert len(lines) == 1 and len(lines[0].xData) == 100
    assert not [i for i in _data_items(view.stiffness) if i.opts["symbol"] is None]

    view.show_diagnosis(diagnosis("explained", None, ranking))
    assert not view.readout_text.isVisible() and not view.readout_plots.isVisible()
    assert view.readout_text.text() == ""
    assert not _data_items(view.stiffness) and not _data_items(view.damping)
    view.show_diagnosis(diagnosis("adequate"))
    assert not view.readout_plots.isVisible()


def test_a_translations_readout_is_labelled_in_metres_and_newtons(qtbot):
    view = DiagnosisView()
    qtbot.addWidget(view)
    ranking = [_ranked(1, 1, "cubic_spring", LOOK_ALIKE)]  # read at point 12 y
    view.show_diagnosis(diagnosis("unexplained", jenkins_readout(rotation=False), ranking))
    assert _axis_text(view.stiffness, "bottom") == "amplitude A [m]"
    assert _axis_text(view.stiffness, "left") == "k_eq [N/m]"
    assert _axis_text(view.damping, "left") == "c_eq [N s/m]"
    # the law read at a place may act at any place that moves as it
    assert "point 12 y moves as point 13 y, spring mount_right_y" in view.readout_text.text()


def test_a_candidates_look_alikes_are_named_in_the_ranking_and_the_verdict(qtbot):
    view = DiagnosisView()
    qtbot.addWidget(view)
    ranking = [_ranked(1, 1, "cubic_spring", LOOK_ALIKE), _ranked(2, 2, "cubic_spring", ALONE)]
    view.show_diagnosis(diagnosis("explained", None, ranking))
    cell = view.ranking.item(0, 2)
    assert cell.text() == "cubic_spring at point 12 y (moves as point 13 y, spring mount_right_y)"
    assert "point 12 y moves as point 13 y, spring mount_right_y" in cell.toolTip()
    assert view.ranking.item(1, 2).text() == "cubic_spring at point 5"
    assert "moves as" not in view.ranking.item(1, 2).toolTip()
    verdict = view.verdict.text()
    assert "cubic_spring at point 12 y" in verdict
    assert "point 12 y moves as point 13 y, spring mount_right_y" in verdict

    # only the best group's places are said under the verdict
    ranking = [_ranked(1, 1, "cubic_spring", ALONE), _ranked(2, 2, "cubic_spring", LOOK_ALIKE)]
    view.show_diagnosis(diagnosis("explained", None, ranking))
    assert "moves as" not in view.verdict.text()
    assert view.ranking.item(1, 2).text().endswith("(moves as point 13 y, spring mount_right_y)")


def test_the_readout_in_the_workbench_fits_the_window(qtbot, lock_dir, joint_readout):
    window = make_window(qtbot, lock_dir)
    window.resize(1400, 900)
    bench = window.workbench
    window.tabs.setCurrentWidget(bench)
    ranking = [
        _ranked(1, 1, "cubic_spring with a joint spring", Location("joint clamp rz")),
        _ranked(2, 2, "coulomb_friction", LOOK_ALIKE),
        _ranked(3, 3, "quadratic_damper", ALONE),
    ]
    bench.diagnosis_view.show_diagnosis(diagnosis("unexplained", joint_readout, ranking))
    bench.tabs.setCurrentWidget(bench.diagnosis_view)
    qtbot.wait(50)
    view = bench.diagnosis_view
    for plot in (view.stiffness, view.damping):
        assert plot.height() >= 160 and plot.width() >= 220
    # the words wrap inside the view: none run off its right edge
    assert view.readout_text.width() <= view.width()
    assert view.readout_text.heightForWidth(view.readout_text.width()) <= view.readout_text.height()
    screenshot(window, "workbench-readout.png")


def test_a_short_logarithmic_x_axis_labels_only_the_powers_of_ten(qtbot):
    axis = LogAxis(orientation="bottom")
    axis.setLogMode(True)
    log_a = (math.log10(6e-6), math.log10(4e-4))  # the amplitudes of the read-out above

    def labelled(size: float) -> list[float]:
        return [round(10**v, 12) for v in axis.tickValues(*log_a, size)[0][1]]

    assert labelled(250) == [1e-5, 1e-4]  # 1, 2, 5 would touch at 140 px a decade
    assert labelled(1500) == [1e-5, 2e-5, 5e-5, 1e-4, 2e-4]
    assert labelled(0) == labelled(1500)  # not yet laid out: as before
