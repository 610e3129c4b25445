"""The rig command line, run as a user runs it (a real pty for the amplifier)."""

import json
import subprocess
import sys

from sim_backend.amplifier import AmplifierModel
from sim_backend.serial_amplifier import SimulatedAmplifierPort


def _run(*args):
    return subprocess.run(
        [sys.executable, "-m", "rig", *args], capture_output=True, text=True, timeout=120
    )


def test_backends_reports_the_missing_ni_driver_and_points_to_sim():
    r = _run("backends", "--json")
    assert r.returncode == 0, r.stderr
    report = json.loads(r.stdout.strip().splitlines()[-1])
    assert set(report) >= {"ni", "sim"}
    if not report["ni"]["available"]:
        assert "--backend sim" in report["ni"]["message"]


def test_amplifier_enable_and_gain_through_a_real_pty():
    model = AmplifierModel()
    with SimulatedAmplifierPort(model) as port:
        r = _run("amplifier", "gain", "4", "--port", port.port, "--json")
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout.strip().splitlines()[-1])["gain_v_per_v"] == 4.0
        r = _run("amplifier", "enable", "--port", port.port, "--json")
        assert json.loads(r.stdout.strip().splitlines()[-1])["enabled"] is True
        assert model.state().enabled


def test_amplifier_without_a_reply_is_a_clear_error():
    with SimulatedAmplifierPort(AmplifierModel()) as port:
        port.silent = True
        r = _run("amplifier", "status", "--port", port.port, "--timeout", "0.2")
    assert r.returncode == 2
    assert "error:" in r.stderr and port.port in r.stderr


def test_run_progress_for_a_parent_process_is_json_lines_with_the_step_count(tmp_path):
    # `rig run --json` (as `rig workflow` calls it): the steps as analysis.progress lines
    import io

    from analysis.progress import parse_line
    from rig.cli.run import ProgressPrinter
    from tests.rig.rig_helpers import reduced_plan, run_on_sim

    stream = io.StringIO()
    printer = ProgressPrinter(stream, json_progress=True)
    plan = reduced_plan(levels_n=(2.0,), ranges=((21.0, 23.0, 1.0),))
    run_on_sim(plan, tmp_path / "p.h5", subscribers=[printer])
    progress = [p for p in map(parse_line, stream.getvalue().splitlines()) if p is not None]
    assert progress and progress[-1].stage == "stepped-sine steps"
    assert (progress[-1].done, progress[-1].total) == (3, 3)
    assert "N at" in progress[-1].note


def test_run_progress_on_a_log_says_the_time_left(tmp_path):
    import io

    from rig.cli.run import ProgressPrinter
    from tests.rig.rig_helpers import reduced_plan, run_on_sim

    stream = io.StringIO()
    plan = reduced_plan(levels_n=(2.0,), ranges=((21.0, 24.0, 1.0),))
    run_on_sim(plan, tmp_path / "p.h5", subscribers=[ProgressPrinter(stream)])
    steps = [ln for ln in stream.getvalue().splitlines() if ln.startswith("step ")]
    assert len(steps) == 4
    assert "left" not in steps[0] and "about" in steps[1] and "left" in steps[1]
    assert "left" not in steps[-1]
