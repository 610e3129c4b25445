"""``python -m benchmarks service --quick``: bounded clients, every event delivered."""

import json
import os
import subprocess
import sys

import pytest


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_service_benchmark_quick_run_loses_no_event():
    env = {k: v for k, v in os.environ.items() if not k.startswith("RIG_")}
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", "service", "--quick"],
        capture_output=True,
        text=True,
        timeout=170,
        env={**env, "OMP_NUM_THREADS": "1"},
    )
    assert r.returncode == 0, r.stderr
    figures = json.loads(r.stdout.strip().splitlines()[-1])
    for key in ("events_lost", "steps_per_s_alone", "steps_per_s_watched"):
        assert key in figures
    assert figures["events_lost"] == 0
    assert figures["run_state_alone"] == figures["run_state_watched"] == "success"
    assert figures["watchers_ended_with_run"] == figures["watchers"] == 3
    assert figures["steps_per_s_alone"] > 0 and figures["steps_per_s_watched"] > 0
    assert figures["request_errors"] == 0 and figures["status_requests"] > 0
