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
