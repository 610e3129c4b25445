"""The acquisition service end to end: real processes, real loopback sockets, real files.

One service (``shared_service``) takes the cut paper plan from one client, is watched by three
others (one of them killed), pauses, resumes, aborts and completes the run; a second run waits
in the queue; requests without the token or with a wrong one are refused and change nothing.
Other services are started, stopped mid-run, killed and restarted to show that the completed
steps survive and that a restarted service reports the interrupted run and completes it.
"""

from __future__ import annotations

import http.client
import json
import signal
import stat
import subprocess
import time

import numpy as np
import pytest

from analysis.measurement_file import read_measurement
from rig.service.client import AuthenticationError, ServiceClient, ServiceError
from rig.service.launch import ensure_service
from tests.rig.service.conftest import CUT_STEPS, rig, wait_for


def _raw(svc, method, path, headers=None, body=None):
    """One HTTP request to the service, as any program could send it."""
    info = json.loads((svc.sdir / "endpoint.json").read_text())
    conn = http.client.HTTPConnection(info["host"], info["port"], timeout=10)
    try:
        conn.request(method, path, body=body, headers=headers or {})
        resp = conn.getresponse()
        return resp.status, dict(resp.getheaders()), resp.read()
    finally:
        conn.close()


def _events(path):
    return [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]


# ------------------------------------------------------------------------ access


@pytest.mark.parametrize(
    "command",
    [
        ["service"],
        ["service", "start"],
        ["service", "stop"],
        ["service", "status"],
        ["submit"],
        ["list"],
        ["watch"],
        ["pause"],
        ["resume"],
        ["abort"],
        ["result"],
    ],
)
def test_help_of_every_service_command(command):
    r = rig(*command, "--help")
    assert r.returncode == 0 and "usage: rig" in r.stdout


@pytest.mark.timeout(60)
def test_the_token_and_the_directory_are_user_only(shared_service):
    sdir = shared_service.sdir
    assert stat.S_IMODE(sdir.stat().st_mode) == 0o700
    for name in ("token", "endpoint.json", "state.json"):
        assert stat.S_IMODE((sdir / name).stat().st_mode) == 0o600, name
    info = json.loads((sdir / "endpoint.json").read_text())
    assert info["host"] == "127.0.0.1"  # loopback by default
    # the announcement follows the endpoint file (which says the service listens) at once
    wait_for(lambda: "token (new)" in shared_service.output(), 20, "the service's announcement")


@pytest.mark.timeout(60)
def test_requests_without_the_token_or_with_a_wrong_one_are_refused(shared_service):
    svc = shared_service
    token = (svc.sdir / "token").read_text().strip()
    runs_before = svc.client().runs()
    submit = json.dumps({"plan": "quick"}).encode()
    json_type = {"Content-Type": "application/json"}
    for headers, expected in (
        ({}, 401),
        ({"Authorization": f"Basic {token}"}, 401),
        ({"Authorization": "Bearer "}, 401),
        ({"Authorization": "Bearer not-the-token-but-long-enough"}, 403),
        ({"Authorization": f"Bearer {token[:-1]}"}, 403),
    ):
        for method, path, body in (
            ("GET", "/api/v1/runs", None),
            ("POST", "/api/v1/runs", submit),
            ("POST", "/api/v1/service/stop", b"{}"),
            ("POST", "/api/v1/runs/current/abort", b"{}"),
            ("GET", "/api/v1/runs/current/events", None),
            ("GET", "/api/v1/no-such-thing", None),
        ):
            status, resp_headers, data = _raw(svc, method, path, {**headers, **json_type}, body)
            assert status == expected, (headers, method, path, data)
            error = json.loads(data)["error"]
            assert error["status"] == expected and error["message"]
            if expected == 401:
                assert resp_headers.get("WWW-Authenticate", "").startswith("Bearer")
    with pytest.raises(AuthenticationError) as info:
        ServiceClient.connect(svc.sdir, token="x" * 43).submit("quick")
    assert info.value.status == 403
    # nothing was executed: no run, and the service still answers
    assert svc.client().runs() == runs_before
    assert svc.proc.poll() is None
    r = svc.cli("service", "status", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["service"]["state"] == "running"


@pytest.mark.timeout(60)
def test_bad_requests_are_refused_with_reasons(shared_service):
    svc = shared_service
    client = svc.client()
    token = client.token
    before = client.runs()
    auth = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}
    for body, code in (
        (b"not json", "bad-json"),
        (b"[1, 2]", "bad-json"),
        (json.dumps({"plan": "/etc/passwd"}).encode(), "bad-plan"),  # names are built-in only
        (json.dumps({"plan": "quick", "out": "../escape.h5"}).encode(), "bad-out"),
        (json.dumps({"plan": "quick", "command": "rm"}).encode(), "bad-field"),
        (json.dumps({"plan": {"name": "x", "kind": "stepped-sine"}}).encode(), "bad-plan"),
    ):
        status, _, data = _raw(svc, "POST", "/api/v1/runs", auth, body)
        assert status == 400, data
        assert json.loads(data)["error"]["code"] == code
    # a plan or a field that does not validate: the answer carries the key path
    plan = {"name": "x", "points": [3], "excitation": {"levels_n": [1.0, -2.0]}}
    for body, path in (
        ({"plan": {**plan, "frequencies": {"ranges": []}}}, ["plan", "excitation", "levels_n", 1]),
        ({"plan": "quick", "pause_on_fault": "yes"}, ["pause_on_fault"]),
    ):
        status, _, data = _raw(svc, "POST", "/api/v1/runs", auth, json.dumps(body).encode())
        assert status == 400 and json.loads(data)["error"]["path"] == path, data
    with pytest.raises(ServiceError) as info:
        client.submit(
            {
                "name": "x",
                "kind": "stepped-sine",
                "points": [3, 99],
                "excitation": {"levels_n": [1.0]},
                "frequencies": {"ranges": [{"start_hz": 20.0, "stop_hz": 21.0, "step_hz": 1.0}]},
            }
        )
    assert info.value.status == 400 and "99" in str(info.value)
    with pytest.raises(ServiceError) as info:
        client.run("r9999")
    assert info.value.status == 404
    assert client.runs() == before


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_one_service_per_directory_and_one_owner_per_device(shared_service, bench, tmp_path):
    svc = shared_service
    sim = ["--backend", "sim", "--setup", bench / "setup.toml", "--port", 0]
    r = rig("service", "start", *sim, "--service-dir", svc.sdir, "--lock-dir", svc.lock_dir)
    assert r.returncode == 2 and "already runs" in r.stderr
    other = tmp_path / "other"
    r = rig("service", "start", *sim, "--service-dir", other, "--lock-dir", svc.lock_dir)
    assert r.returncode == 2 and f"in use by process {svc.proc.pid}" in r.stderr
    assert not (other / "endpoint.json").exists()
    out = tmp_path / "x.h5"
    r = rig("run", "quick", *sim[:4], "--out", out, "--lock-dir", svc.lock_dir)
    assert r.returncode == 2, r.stderr
    assert f"in use by process {svc.proc.pid}" in r.stderr
    assert not out.exists()


# ------------------------------------------------------------------------ a run, watched


def _watched_to_the_end(client, run_a, watchers, outs, n_aborted: int) -> list:
    """The watchers still connected end by themselves and have every event, in order;
    returns the run's events as the service holds them."""
    for w in watchers[1:]:
        assert w.wait(30) == 1  # the run ended, not successfully
    held = list(client.events(run_a, follow=False))
    for out in outs[1:]:
        events = _events(out)
        assert [e["seq"] for e in events] == list(range(1, len(events) + 1))
        assert events == held[: len(events)]
        assert events[-1]["type"] == "RunState" and events[-1]["data"]["state"] == "aborted"
        kinds = [e["type"] for e in events]
        assert kinds.count("StepFinished") == n_aborted
        for kind in (
            "RunStarted",
            "PretestFinished",
            "ControlIteration",
            "RunPaused",
            "RunResumed",
            "RunFinished",
        ):
            assert kind in kinds
    return held


def _resume_completes(svc, client, run_a, run_b, held, n_aborted: int, data) -> None:
    """Resume completes the file; a late watcher picks up where the first ones stopped."""
    last_seq = held[-1]["seq"]
    r = svc.cli("resume", run_a, "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["state"] in ("queued", "running")
    with client.events(run_a, since=last_seq) as stream:
        more = list(stream)
    assert stream.end["state"] == "success" and stream.lost == 0, (
        stream.end,
        client.run(run_a)["message"],
    )
    assert [e["seq"] for e in more] == list(range(last_seq + 1, last_seq + 1 + len(more)))
    assert [e["type"] for e in more].count("StepFinished") == CUT_STEPS - n_aborted
    record = client.run(run_a)
    assert record["state"] == "success" and record["attempts"] == 2
    done = read_measurement(record["path"])
    assert done.complete and done.exit_status == "success" and done.n_steps == CUT_STEPS
    assert sorted(done.plan_index) == list(range(CUT_STEPS))
    np.testing.assert_array_equal(done.frequency_hz[:n_aborted], data.frequency_hz)

    result = client.result(run_a)
    assert result["exists"] and result["summary"]["n_done"] == CUT_STEPS
    assert result["summary"]["written_this_run"] == CUT_STEPS - n_aborted
    assert result["summary"]["wall_s"] > 0 and result["summary"]["rig_time_s"] > 0
    r = svc.cli("list", "--json")
    states = {x["id"]: x["state"] for x in json.loads(r.stdout)}
    assert states[run_a] == states[run_b] == "success"


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_paper_run_watched_by_three_paused_aborted_and_resumed(
    shared_service, procs, bench, tmp_path
):
    svc = shared_service
    client = svc.client()
    plan = bench / "paper_cut.toml"
    r = svc.cli("submit", plan, "--label", "paper cut, at 5120 Hz", "--json")
    assert r.returncode == 0, r.stderr
    run_a = json.loads(r.stdout)["id"]
    run_b = client.submit("quick", label="second")

    outs = [tmp_path / f"watch{i}.ndjson" for i in range(3)]
    watchers = []
    for out in outs:
        with open(out, "w") as fh:
            watchers.append(
                procs.popen(["watch", run_a, "--json", "--service-dir", svc.sdir], stdout=fh)
            )
    wait_for(lambda: len(_events(outs[0])) >= 20, 30, "the first watcher to see events")
    assert client.run(run_b)["state"] == "queued"  # the second run waits for the first
    assert client.status()["queued"] == [run_b]

    watchers[0].send_signal(signal.SIGKILL)  # a client crashes: nothing changes for the run
    watchers[0].wait(10)
    n_killed = len(_events(outs[0]))

    r = svc.cli("pause", run_a)
    assert r.returncode == 0, r.stderr
    wait_for(lambda: client.run(run_a)["state"] == "paused", 20, "the run to pause")
    n_paused = client.run(run_a)["n_done"]
    assert 3 <= n_paused < CUT_STEPS
    time.sleep(1.0)
    record = client.run(run_a)
    assert record["state"] == "paused" and record["n_done"] == n_paused
    assert client.status()["current"]["id"] == run_a

    r = svc.cli("resume")  # the current run
    assert r.returncode == 0, r.stderr
    wait_for(lambda: client.run(run_a)["n_done"] >= n_paused + 3, 30, "steps after resuming")
    r = svc.cli("abort", run_a, "--reason", "enough for now")
    assert r.returncode == 0, r.stderr
    record = client.wait(run_a, 30)
    assert record["state"] == "aborted" and record["resumable"]
    n_aborted = record["n_done"]
    assert n_paused + 3 <= n_aborted < CUT_STEPS

    held = _watched_to_the_end(client, run_a, watchers, outs, n_aborted)
    assert n_killed < len(_events(outs[1]))

    # the event's arrays: complex phasors as [re, im] pairs
    step = next(e for e in held if e["type"] == "StepFinished")["data"]["record"]
    force = np.array(step["force"])
    assert force.shape == (3, 2) and abs(np.hypot(*force[0]) - 2.0) < 0.1

    # the file keeps every completed step; the output was ramped down
    data = read_measurement(record["path"])
    assert data.exit_status == "aborted" and "enough for now" in data.exit_message
    assert "ramped to 0 V" in data.exit_message
    assert data.n_steps == n_aborted
    assert list(data.plan_index) == list(range(n_aborted))

    # the queued run ran once the first had ended
    record_b = client.wait(run_b, 60)
    assert record_b["state"] == "success" and record_b["n_done"] == 10
    assert record_b["started_s"] >= record["finished_s"]

    _resume_completes(svc, client, run_a, run_b, held, n_aborted, data)


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_submit_and_watch_from_the_command_line(shared_service):
    r = shared_service.cli("submit", "quick", "--watch", timeout=60)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("run r") and "quick, 10 steps" in lines[0]
    assert sum(line.startswith("step ") for line in lines) == 10
    assert any(line.startswith("step 10/10 ") for line in lines)
    assert "finished success" in lines and lines[-1].endswith("success (10/10 steps)")
    run_id = lines[0].split()[1]
    r = shared_service.cli("result", run_id)
    assert r.returncode == 0 and "status    success; 10 of 10 steps on disk" in r.stdout
    r = shared_service.cli("resume", run_id)  # a complete run has nothing to resume
    assert r.returncode == 2 and "cannot be resumed" in r.stderr
    r = shared_service.cli("pause")  # nothing under way
    assert r.returncode == 2 and "no run is under way" in r.stderr


# ------------------------------------------------------------------------ stop and restart


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_start_detached_status_and_stop(procs, tmp_path, bench):
    sdir = tmp_path / "svc"
    common = ["--service-dir", sdir]
    r = rig("service", "status", *common)
    assert r.returncode == 3 and "not running" in r.stdout
    r = rig(
        "service",
        "start",
        "--detach",
        "--backend",
        "sim",
        "--setup",
        bench / "setup.toml",
        "--port",
        0,
        "--lock-dir",
        tmp_path / "locks",
        *common,
    )
    info = json.loads((sdir / "endpoint.json").read_text())
    procs.pids.append(info["pid"])
    assert r.returncode == 0, r.stderr
    assert f"process {info['pid']}" in r.stdout
    r = rig("service", "status", "--json", *common)
    assert r.returncode == 0, r.stderr
    status = json.loads(r.stdout)
    assert status["running"] and status["service"]["pid"] == info["pid"]
    assert status["service"]["backend"] == "sim" and status["current"] is None
    assert ensure_service(sdir).status()["service"]["pid"] == info["pid"]  # the one running
    r = rig("service", "stop", *common)
    assert r.returncode == 0, r.stderr
    wait_for(lambda: not _pid_alive(info["pid"]), 20, "the service to exit")
    assert not (sdir / "endpoint.json").exists()
    r = rig("service", "status", *common)
    assert r.returncode == 3
    r = rig("submit", "quick", *common)
    assert r.returncode == 3 and "no acquisition service is running" in r.stderr

    # a GUI or a script that finds no service starts one
    client = ensure_service(sdir, setup=bench / "setup.toml", port=0, lock_dir=tmp_path / "locks")
    pid = client.status()["service"]["pid"]
    procs.pids.append(pid)
    assert pid != info["pid"]
    client.stop_service()
    wait_for(lambda: not _pid_alive(pid), 20, "the second service to exit")


def _pid_alive(pid: int) -> bool:
    try:
        subprocess.run(["kill", "-0", str(pid)], check=True, capture_output=True)
    except subprocess.CalledProcessError:
        return False
    return True


def _stopped_cleanly(svc, run_id):
    """A clean stop: the run is ended through the engine and recorded as interrupted; returns
    its file's data."""
    r = svc.cli("service", "stop", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["interrupted"] == run_id
    assert json.loads(r.stdout)["output_at_zero"] is True  # read from the run's file
    assert svc.wait_exit(30) == 0
    # the service is gone: its state and the file tell what happened
    state = json.loads((svc.sdir / "state.json").read_text())
    record = next(x for x in state["runs"] if x["id"] == run_id)
    assert record["state"] == "interrupted"
    data = read_measurement(record["path"])
    assert data.exit_status == "aborted" and "service was stopped" in data.exit_message
    assert "ramped to 0 V" in data.exit_message
    n_stopped = data.n_steps
    assert 5 <= n_stopped < CUT_STEPS and record["n_done"] == n_stopped
    assert list(data.plan_index) == list(range(n_stopped))
    return data


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_stop_and_kill_mid_run_then_restart_reports_and_resumes(service_factory, bench):
    svc = service_factory().start()
    client = svc.client()
    run_id = client.submit(bench / "paper_cut.toml")
    wait_for(lambda: client.run(run_id)["n_done"] >= 5, 60, "five steps")

    # a clean stop: the run is ended through the engine and recorded as interrupted
    data = _stopped_cleanly(svc, run_id)
    n_stopped = data.n_steps

    # restart: the interrupted run is reported; resume continues it
    svc.start()
    wait_for(lambda: f"rig resume {run_id}" in svc.output(), 20, "the service's announcement")
    assert f"{run_id} paper_cut: {n_stopped}/{CUT_STEPS} steps" in svc.output()
    client = svc.client()
    status = client.status()
    assert status["interrupted"] == [run_id] and status["current"] is None
    time.sleep(0.5)
    assert client.run(run_id)["n_done"] == n_stopped  # nothing starts by itself
    r = svc.cli("resume", run_id)
    assert r.returncode == 0, r.stderr
    wait_for(lambda: client.run(run_id)["n_done"] >= n_stopped + 5, 60, "resumed steps")

    # a crash (SIGKILL) mid-run: the steps on disk survive, the restart reports the run
    svc.proc.send_signal(signal.SIGKILL)
    svc.wait_exit(10)
    svc.start()
    client = svc.client()
    record = client.run(run_id)
    assert record["state"] == "interrupted" and record["resumable"]
    assert "under way" in record["message"]
    on_disk = read_measurement(record["path"])
    assert on_disk.exit_status == "running"  # nobody could record the end
    assert record["n_done"] == on_disk.n_steps > n_stopped  # counted in the file on restart
    assert client.status()["interrupted"] == [run_id]
    client.resume(run_id)
    record = client.wait(run_id, 90)
    assert record["state"] == "success" and record["attempts"] == 3, record
    done = read_measurement(record["path"])
    assert done.complete and done.n_steps == CUT_STEPS
    assert sorted(done.plan_index) == list(range(CUT_STEPS))
    np.testing.assert_array_equal(done.frequency_hz[:n_stopped], data.frequency_hz)
    with client.events(run_id, follow=False) as stream:
        seqs = [e["seq"] for e in stream]
    assert seqs == list(range(1, len(seqs) + 1))  # one log across three processes
    r = svc.cli("service", "stop")
    assert r.returncode == 0, r.stderr
    assert svc.wait_exit(30) == 0
