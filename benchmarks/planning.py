"""Pretest planning speed and the paper's findings on the reference rig.

All 14 700 candidate configurations of the paper's Table 3 (or the quick set), ranked by
det(FIM) on the rig with the paper's calibrated linear values and the nominal contact, the
sweeps on a local process pool (one worker per core). Figures: ``planning_s`` (wall time,
sweeps included), ``n_configurations``, ``top`` (the paper's Table 4), ``kc_gap_mac_1hz`` and
``kc_gap_mac_refined`` (correlation index of k_c and gap of the chosen configuration with
1 Hz steps, and with 0.1 Hz steps added in 24-28 Hz), and the same for the paper's own choice
(actuator 3, levels 2/4/6 N, sensors 3/6/7).
"""

from __future__ import annotations

import os
import time

import numpy as np

from analysis.model import load_model
from analysis.planning import (
    PAPER_LINEAR,
    Candidates,
    Configuration,
    open_executor,
    paper_candidates,
    plan_tests,
    quick_candidates,
)

PAPER_CHOICE = Configuration(3, (3, 6, 7), (2.0, 4.0, 6.0), paper_candidates().ranges[0])


def run(quick: bool = False) -> dict:
    model = load_model().with_values(PAPER_LINEAR)
    cand = quick_candidates() if quick else paper_candidates()
    workers = os.cpu_count() or 1
    t0 = time.perf_counter()
    with open_executor(workers) as executor:
        result = plan_tests(model, cand, executor=executor)
    planning_s = time.perf_counter() - t0
    print(result.format_table())
    # the paper's own choice: its place in this ranking and its correlation study
    paper_rank = None if quick else result.rank_of(PAPER_CHOICE)
    paper = None
    if not quick:
        only = Candidates(
            sensors=PAPER_CHOICE.sensors,
            actuators=(PAPER_CHOICE.actuator,),
            levels_n=PAPER_CHOICE.levels_n,
            ranges=(PAPER_CHOICE.frequency_range,),
        )
        paper = plan_tests(model, only, executor=None)
    i, j = result.parameters.index("k_c"), result.parameters.index("gap")
    figures = {
        "planning_s": round(planning_s, 3),
        "workers": workers,
        "n_configurations": result.n_configurations,
        "n_identifiable": result.n_identifiable,
        "n_sweeps": result.n_sweeps,
        "n_steps": result.n_steps,
        "failed_steps": result.failed_steps,
        "sweeps_s": round(result.timings["sweeps"], 3),
        "ranking_s": round(result.timings["ranking"], 4),
        "top": [r.to_dict() for r in result.top],
        "fim_inverse": result.to_dict()["correlations"]["fim_inverse"],
        "kc_gap_mac_1hz": round(result.correlations.pair(i, j), 4),
        "kc_gap_mac_refined": (
            None if result.refined is None else round(result.refined.pair(i, j), 4)
        ),
        "kc_gap_mac_frf_1hz": round(result.correlations.pair(i, j, frf=True), 4),
        "kc_gap_mac_frf_refined": (
            None if result.refined is None else round(result.refined.pair(i, j, frf=True), 4)
        ),
    }
    if paper is not None:
        figures["paper_choice_rank"] = paper_rank.rank
        figures["paper_choice_log10_det"] = round(paper_rank.log10_det, 3)
        figures["paper_choice_kc_gap_mac_1hz"] = round(paper.correlations.pair(i, j), 4)
        figures["paper_choice_kc_gap_mac_refined"] = round(paper.refined.pair(i, j), 4)
    print()
    print(f"{'figure':<34}{'value':>12}")
    for key in (
        "planning_s",
        "n_configurations",
        "n_identifiable",
        "n_sweeps",
        "n_steps",
        "kc_gap_mac_1hz",
        "kc_gap_mac_refined",
        "kc_gap_mac_frf_1hz",
        "kc_gap_mac_frf_refined",
        "paper_choice_rank",
        "paper_choice_kc_gap_mac_1hz",
        "paper_choice_kc_gap_mac_refined",
    ):
        if key in figures:
            v = figures[key]
            print(f"{key:<34}{v if v is not None else '-':>12}")
    assert np.isfinite(planning_s)
    return figures
