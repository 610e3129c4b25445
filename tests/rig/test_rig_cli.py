"""``python -m rig`` run, linear, export-uff and plans, run as a user runs them (subprocesses)."""

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest
import tomli_w

from analysis.measurement_file import read_measurement
from rig.config.plans import builtin_plans
from rig.config.setup import load_setup

ENV = {**os.environ, "OMP_NUM_THREADS": "1"}


def _rig(*args, timeout=120):
    return subprocess.run(
        [sys.executable, "-m", "rig", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=ENV,
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A setup at 5120 Hz, a 22-step stepped-sine plan and a short random plan."""
    d = tmp_path_factory.mktemp("cli")
    setup = load_setup("reference").with_sample_rate(5120.0).to_dict()
    (d / "setup.toml").write_bytes(tomli_w.dumps(setup).encode())
    text = builtin_plans()["quick"].read_text()
    text = text.replace("levels_n = [2.0, 8.0]", "levels_n = [2.0, 4.0]")
    text = text.replace("start_hz = 23.0, stop_hz = 27.0", "start_hz = 21.0, stop_hz = 23.0")
    text = text.replace("step_hz = 1.0 }", "step_hz = 0.2 }")
    (d / "steps.toml").write_text(text.replace('name = "quick"', 'name = "cli-test"'))
    text = builtin_plans()["linear"].read_text()
    text = text.replace("record_s = 8.0", "record_s = 1.0").replace(
        "average_records = 64", "average_records = 3"
    )
    (d / "random.toml").write_text(text.replace("noise_s = 2.0", "noise_s = 0.5"))
    return d


@pytest.mark.parametrize(
    "command", ["run", "linear", "export-uff", "plans", "backends", "amplifier", None]
)
def test_help_everywhere(command):
    r = _rig(*([command] if command else []), "--help")
    assert r.returncode == 0 and "usage: rig" in r.stdout


def test_plans_lists_the_builtin_plans():
    r = _rig("plans", "--json")
    assert r.returncode == 0, r.stderr
    plans = json.loads(r.stdout)
    assert {"paper", "quick", "linear"} <= set(plans)
    assert "224 steps" in plans["paper"]["summary"] and plans["linear"]["kind"] == "random"


@pytest.mark.slow
def test_ni_backend_without_driver_points_to_sim(files, tmp_path):
    r = _rig("run", "quick", "--backend", "ni", "--out", tmp_path / "x.h5", "--lock-dir", tmp_path)
    if r.returncode == 0:  # pragma: no cover - a machine with NI-DAQmx and hardware
        pytest.skip("NI-DAQmx is installed here")
    assert r.returncode == 2 and "--backend sim" in r.stderr
    assert not (tmp_path / "x.h5").exists()
    r = _rig("run", "linear", "--out", tmp_path / "y.h5", "--lock-dir", tmp_path)
    assert r.returncode == 2 and "use 'rig linear'" in r.stderr


def _start(files, out, *extra):
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rig",
            "run",
            files / "steps.toml",
            "--backend",
            "sim",
            "--setup",
            files / "setup.toml",
            "--out",
            out,
            "--lock-dir",
            files,
            *map(str, extra),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
    )


def _wait_for_step(proc, n, deadline_s=60.0):
    """Read the child's progress lines until step n is reported; return the lines."""
    lines = []
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        m = re.match(r"step (\d+)/(\d+)", line)
        if m and int(m.group(1)) >= n:
            return lines
    raise AssertionError(f"step {n} never reported: {''.join(lines)}")


@pytest.mark.slow
def test_sigkill_mid_run_leaves_a_file_that_resume_completes(files, tmp_path):
    out = tmp_path / "killed.h5"
    proc = _start(files, out)
    lines = _wait_for_step(proc, 3)
    proc.send_signal(signal.SIGKILL)
    proc.wait(30)
    reported = max(int(m.group(1)) for m in re.finditer(r"step (\d+)/", "".join(lines)))
    data = read_measurement(out)
    assert data.exit_status == "running" and not data.complete
    assert reported <= data.n_steps < 22  # every step reported done is on disk
    assert list(data.plan_index) == list(range(data.n_steps))
    r = _rig("run", "--resume", out, "--backend", "sim", "--lock-dir", files, "--json", timeout=180)
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert summary["status"] == "success" and summary["n_done"] == 22
    assert summary["written_this_run"] == 22 - data.n_steps
    done = read_measurement(out)
    assert done.complete and sorted(done.plan_index) == list(range(22))


@pytest.mark.slow
def test_ctrl_c_stops_cleanly(files, tmp_path):
    out = tmp_path / "interrupted.h5"
    proc = _start(files, out)
    _wait_for_step(proc, 2)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    data = read_measurement(out)
    assert data.exit_status == "aborted" and "interrupted by the user (Ctrl-C)" in data.exit_message
    assert "Output ramped to 0 V" in data.exit_message and data.n_steps >= 2
    assert "resume    python -m rig run --resume" in stdout


@pytest.mark.slow
def test_run_linear_and_export(files, tmp_path):
    out = tmp_path / "run.h5"
    r = _rig(
        "run",
        files / "steps.toml",
        "--backend",
        "sim",
        "--setup",
        files / "setup.toml",
        "--out",
        out,
        "--lock-dir",
        files,
        "--seed",
        "3",
    )
    assert r.returncode == 0, r.stderr
    assert "steps     22 of 22 on disk" in r.stdout and "converged" in r.stdout
    assert re.search(r"step 22/22 \[#+\]", r.stderr)
    lin = tmp_path / "lin.h5"
    r = _rig(
        "linear",
        files / "random.toml",
        "--backend",
        "sim",
        "--setup",
        files / "setup.toml",
        "--out",
        lin,
        "--lock-dir",
        files,
        "--json",
    )
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.strip().splitlines()[-1])["status"] == "success"
    data = read_measurement(lin)
    assert data.exit_status == "success" and data.h1.shape[1] == 14 and data.n_averages == 3
    for source, n in ((out, 2 * 3 * 3), (lin, 13)):
        r = _rig("export-uff", source, tmp_path / f"{source.stem}.uff", "--json")
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["sets"] == n
    r = _rig("export-uff", out, tmp_path / "run.uff")
    assert r.returncode == 2 and "file exists" in r.stderr


def test_top_level_help_lists_each_command_once():
    """``rig --help`` names every command on one line of its own, once."""
    from rig.cli.main import build_parser

    text = build_parser().format_help()
    names = list(build_parser()._subparsers._group_actions[0].choices)
    assert len(names) > 10
    for name in names:
        lines = [ln for ln in text.splitlines() if ln.split()[:1] == [name]]
        assert len(lines) == 1, (name, lines)
    assert "{" not in text  # no {a,b,...} list of every command in the usage


@pytest.mark.slow
def test_an_existing_output_file_names_the_command_line_flag(tmp_path):
    """The library says overwrite=True; a command-line user reads --overwrite."""
    for command in ("run", "linear"):
        out = tmp_path / f"{command}.h5"
        out.write_bytes(b"")
        plan = ["quick"] if command == "run" else []
        r = _rig(command, *plan, "--backend", "sim", "--out", out, "--lock-dir", tmp_path)
        assert r.returncode == 2, r.stderr
        assert f"{out}: file exists (pass --overwrite to replace it)" in r.stderr
        assert "overwrite=True" not in r.stderr and "Traceback" not in r.stderr


def test_the_library_keeps_its_own_wording_and_the_cli_rephrases_each_kind(tmp_path):
    from analysis.measurement_file import OutputExistsError
    from analysis.measurement_file.layout import build_file
    from rig.cli.main import file_exists_message

    out = tmp_path / "x.h5"
    out.write_bytes(b"")
    with pytest.raises(OutputExistsError, match=r"pass overwrite=True") as info:
        build_file(out, False, lambda f: None)
    assert isinstance(info.value, FileExistsError) and info.value.path == out
    assert file_exists_message(info.value) == f"{out}: file exists (pass --overwrite to replace it)"
    for text in ("pass overwrite to replace it", "use --overwrite to replace it"):
        msg = file_exists_message(FileExistsError(f"{out}: file exists ({text})"))
        assert msg == f"{out}: file exists (pass --overwrite to replace it)"


@pytest.mark.slow
def test_a_simulated_fault_switched_on_from_the_command_line(files, tmp_path):
    out = tmp_path / "fault.h5"
    r = _rig(
        "run",
        files / "steps.toml",
        "--setup",
        files / "setup.toml",
        "--out",
        out,
        "--backend",
        "sim",
        "--lock-dir",
        files,
        "--json",
        "--fault",
        "acc7:disconnect@step3",
    )
    assert r.returncode != 0
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert summary["status"] == "aborted" and summary["n_done"] == 2, summary
    data = read_measurement(out)
    assert "'acc7'" in data.exit_message and data.n_steps == 2
    assert data.config["run"]["argv"][-2:] == ["--fault", "acc7:disconnect@step3"]


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("acc7:disconect@step3", "unknown fault 'disconect'"),
        ("acc7:disconnect@3", "the step is written @stepN"),
        ("acc7:disconnect@step0", "steps are counted from 1"),
        ("disconnect", "'disconnect' needs a channel"),
        ("acc7:clip", "clip needs a level"),
        ("acc7:clip=-2", "must be a number > 0"),
        ("acc7:clip=lots", "the level 'lots' is not a number"),
        ("acc99:disconnect", "no channel 'acc99' in the setup"),
        ("acc7:read-timeout", "concerns the whole rig"),
    ],
)
@pytest.mark.slow
def test_a_bad_fault_is_refused_with_the_syntax(files, tmp_path, spec, expected):
    r = _rig(
        "run",
        files / "steps.toml",
        "--setup",
        files / "setup.toml",
        "--out",
        tmp_path / "x.h5",
        "--backend",
        "sim",
        "--lock-dir",
        files,
        "--fault",
        spec,
    )
    assert r.returncode == 2, r.stderr
    assert expected in r.stderr and f"--fault {spec!r}" in r.stderr
    assert "Traceback" not in r.stderr
    if "setup" not in expected:
        assert "[CHANNEL:]KIND[=LEVEL][@stepN]" in r.stderr
    assert not (tmp_path / "x.h5").exists()


def test_fault_specs_parse():
    from rig.run.faults import SimFault, parse_sim_fault

    assert parse_sim_fault("acc7:disconnect@step3") == SimFault("disconnect", "acc7", None, 3)
    assert parse_sim_fault("acc7:clip=12") == SimFault("clip", "acc7", 12.0, 1)
    assert parse_sim_fault("read-timeout@step2") == SimFault("read-timeout", "", None, 2)
    assert parse_sim_fault("amplifier-overload").kind == "amplifier-overload"
