"""The ``--scheduler`` path on a real Dask cluster (``distributed.LocalCluster`` on loopback).

The scheduler and one worker (one thread, no dashboard) run in this process; the command
connects to the scheduler's TCP address as it would to a lab cluster, and its jobs are
pickled to the worker and back. Needs the ``dask`` extra (``distributed``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from analysis.cli import main
from analysis.model import load_model

from .synthetic_runs import write_synthetic_run

distributed = pytest.importorskip("distributed")

pytestmark = pytest.mark.slow

LINEAR = {
    "E_frame": 205e9,
    "E_corner": 128e9,
    "E_beam": 201e9,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
}
TRUTH = {"k_c": 4.51e5, "gap": 0.60e-3, "v_c": 25.21}


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        protocol="tcp",
        host="127.0.0.1",
        dashboard_address=None,
    ) as c:
        assert c.scheduler_address.startswith("tcp://127.0.0.1:")
        yield c


def _tasks_done(cluster) -> int:
    """Tasks the cluster's scheduler has seen finish (over every client)."""
    prefixes = cluster.scheduler.task_prefixes.values()
    return sum(
        sum(p.state_counts.get(s, 0) for s in ("memory", "released", "forgotten")) for p in prefixes
    )


def test_a_reduced_calibration_runs_on_the_cluster(cluster, tmp_path, capsys) -> None:
    freqs = np.unique(
        np.round(np.concatenate([[22.0, 24.0], np.arange(25.0, 28.01, 0.5), [30.0, 33.0]]), 6)
    )
    run = write_synthetic_run(
        tmp_path / "run.h5",
        load_model().with_values({**LINEAR, **TRUTH}),
        levels_n=(2.0, 5.0, 8.0),
        frequencies_hz=freqs,
        seed=3,
    )
    sets = [a for k, v in LINEAR.items() for a in ("--set", f"{k}={v}")]
    before = _tasks_done(cluster)
    code = main(
        [
            "calibrate",
            str(run),
            *sets,
            "--out",
            str(tmp_path / "cal"),
            "--starts",
            "4",
            "--max-iterations",
            "3",
            "--scheduler",
            cluster.scheduler_address,
            "--json",
        ]
    )
    out = capsys.readouterr()
    assert code == 0, out.err
    result = json.loads(out.out.strip().splitlines()[-1])
    assert set(TRUTH) <= set(result["parameters"])
    assert (tmp_path / "cal" / "calibration.json").exists()
    assert _tasks_done(cluster) - before >= 4  # the Latin hypercube starts ran there


def test_a_plan_runs_on_the_cluster(cluster, capsys) -> None:
    before = _tasks_done(cluster)
    code = main(
        [
            "plan",
            "--quick",
            "--no-refine",
            "--top",
            "3",
            "--scheduler",
            cluster.scheduler_address,
            "--json",
        ]
    )
    out = capsys.readouterr()
    assert code == 0, out.err
    result = json.loads(out.out.strip().splitlines()[-1])
    assert result["n_configurations"] > 0 and len(result["top"]) == 3
    assert _tasks_done(cluster) > before  # the sweeps ran there
