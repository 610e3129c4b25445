"""Acquisition service under load: events lost and the run's step rate with and without watchers.

A service process on the simulated rig (``python -m rig service start --backend sim``, a
temporary service directory, a free loopback port) runs the same plan twice:

0. a warm-up run of the quick plan (the simulated rig builds its model on first use);
1. alone: nothing but the submitting client;
2. watched: ``N`` watcher processes stream every event of the run (each checks that the
   ``seq`` numbers have no gap and that the stream ends with the run) and ``M`` poller
   processes ask for the status at 10 Hz (at most ``requests`` each), as GUIs and scripts
   would.

Every client is bounded (a request count and a deadline) and stops by itself when the run
ends. ``events_lost`` counts, over all watchers, the events of the run (as the service
numbered them) that a watcher did not receive; it must be 0. The step rate is steps on disk
over the run's wall time (start to end as the service recorded them).

Full run: the paper plan (224 steps) on the reference setup at 10.24 kHz, 8 watchers and 2
pollers; ``--quick``: the quick plan (10 steps) at 5.12 kHz, 3 watchers and 1 poller.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import tomli_w

from rig.config.setup import load_setup
from rig.service.client import FINAL_STATES, ServiceClient

ENV_DROP = ("RIG_SERVICE_DIR", "RIG_SERVICE_URL", "RIG_SERVICE_TOKEN", "RIG_LOCK_DIR")


# ------------------------------------------------------------------------ the clients


def _find_run(client: ServiceClient, label: str, deadline: float) -> str | None:
    while time.monotonic() < deadline:
        for r in client.runs():
            if r.get("label") == label:
                return r["id"]
        time.sleep(0.05)
    return None


def _watcher(service_dir: str, label: str, timeout_s: float) -> dict:
    """Stream every event of the run labelled ``label``; report what arrived."""
    client = ServiceClient.connect(service_dir)
    client.status()
    print("ready", flush=True)
    deadline = time.monotonic() + timeout_s
    run_id = _find_run(client, label, deadline)
    if run_id is None:
        return {"error": "no run appeared"}
    seqs, latencies = [], []
    with client.events(run_id) as stream:
        for event in stream:
            seqs.append(event["seq"])
            if event.get("time_s"):
                latencies.append(time.time() - event["time_s"])
            if time.monotonic() > deadline:
                break
        end = stream.end
    return {
        "run": run_id,
        "received": len(seqs),
        "distinct": len(set(seqs)),
        "first": seqs[0] if seqs else None,
        "last": seqs[-1] if seqs else None,
        "gaps": stream.lost,
        "end_state": end.get("state") if end else None,
        "latency_ms": [round(1e3 * x, 3) for x in latencies[-200:]],
    }


def _poller(service_dir: str, label: str, timeout_s: float, requests: int) -> dict:
    """Ask for the status at 10 Hz until the run ends (at most ``requests`` times)."""
    client = ServiceClient.connect(service_dir)
    client.status()
    print("ready", flush=True)
    deadline = time.monotonic() + timeout_s
    run_id = _find_run(client, label, deadline)
    times, errors = [], 0
    for _ in range(requests):
        t0 = time.perf_counter()
        try:
            record = client.run(run_id)
        except Exception:
            errors += 1
            record = {"state": "?"}
        times.append(time.perf_counter() - t0)
        if record["state"] in FINAL_STATES or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    return {"requests": len(times), "errors": errors, "ms": [1e3 * t for t in times]}


def _child_main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("role", choices=("watcher", "poller"))
    p.add_argument("--service-dir", required=True)
    p.add_argument("--label", required=True)
    p.add_argument("--timeout", type=float, required=True)
    p.add_argument("--requests", type=int, default=100)
    a = p.parse_args()
    if a.role == "watcher":
        out = _watcher(a.service_dir, a.label, a.timeout)
    else:
        out = _poller(a.service_dir, a.label, a.timeout, a.requests)
    print(json.dumps(out), flush=True)
    return 0


# ------------------------------------------------------------------------ the scenario


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ENV_DROP}
    env["OMP_NUM_THREADS"] = "1"
    return env


def _start_service(work: Path, setup_file: Path) -> tuple[subprocess.Popen, Path]:
    sdir = work / "service"
    log = open(work / "service.log", "w")  # noqa: SIM115 - the child writes to it
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rig",
            "service",
            "start",
            "--backend",
            "sim",
            "--setup",
            str(setup_file),
            "--service-dir",
            str(sdir),
            "--port",
            "0",
            "--lock-dir",
            str(work / "locks"),
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=_env(),
    )
    log.close()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError("the service did not start:\n" + (work / "service.log").read_text())
        try:
            if json.loads((sdir / "endpoint.json").read_text()).get("pid") == proc.pid:
                return proc, sdir
        except (OSError, ValueError):
            pass
        time.sleep(0.05)
    proc.kill()
    raise RuntimeError("the service did not answer within 60 s")


def _clients(sdir: Path, label: str, n_watch: int, n_poll: int, timeout_s: float, requests: int):
    procs = []
    for role, n in (("watcher", n_watch), ("poller", n_poll)):
        for _ in range(n):
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "benchmarks.service",
                        role,
                        "--service-dir",
                        str(sdir),
                        "--label",
                        label,
                        "--timeout",
                        str(timeout_s),
                        "--requests",
                        str(requests),
                    ],
                    stdout=subprocess.PIPE,
                    text=True,
                    env=_env(),
                )
            )
    for proc in procs:  # every client has connected before the run is submitted
        line = proc.stdout.readline()
        if line.strip() != "ready":
            raise RuntimeError(f"a client did not start: {line!r}")
    return procs


def _run(client: ServiceClient, plan: str, label: str, timeout_s: float) -> dict:
    run_id = client.submit(plan, label=label)
    record = client.wait(run_id, timeout_s, poll_s=0.5)
    wall = record["finished_s"] - record["started_s"]
    record["steps_per_s"] = record["n_done"] / wall if wall > 0 else float("nan")
    record["wall_s"] = wall
    return record


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q * (len(values) - 1))))]


def run(quick: bool = False) -> dict:
    plan, fs = ("quick", 5120.0) if quick else ("paper", 10240.0)
    n_watch, n_poll, requests = (3, 1, 100) if quick else (8, 2, 1000)
    timeout_s = 120.0 if quick else 600.0
    with tempfile.TemporaryDirectory(prefix="rig-service-bench-") as tmp:
        work = Path(tmp)
        setup = load_setup("reference").with_sample_rate(fs).to_dict()
        (work / "setup.toml").write_bytes(tomli_w.dumps(setup).encode())
        service, sdir = _start_service(work, work / "setup.toml")
        clients: list[subprocess.Popen] = []
        try:
            client = ServiceClient.connect(sdir)
            _run(client, "quick", "warm-up", timeout_s)  # builds and caches the rig model
            alone = _run(client, plan, "alone", timeout_s)
            print(
                f"alone:   {alone['n_done']} steps of {plan} at {fs:g} Hz in "
                f"{alone['wall_s']:.2f} s: {alone['steps_per_s']:.2f} steps/s ({alone['state']})"
            )
            clients = _clients(sdir, "watched", n_watch, n_poll, timeout_s, requests)
            watched = _run(client, plan, "watched", timeout_s)
            reports = []
            for proc in clients:
                out, _ = proc.communicate(timeout=60)
                reports.append(json.loads(out.strip().splitlines()[-1]))
            client.stop_service()
            service.wait(60)
        finally:
            for proc in [*clients, service]:
                if proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
                    try:
                        proc.wait(30)
                    except subprocess.TimeoutExpired:
                        proc.kill()
    watchers = [r for r in reports if "received" in r or "error" in r][:n_watch]
    pollers = reports[n_watch:]
    total = watched["events"]
    lost = sum(total - r.get("distinct", 0) for r in watchers)
    latencies = [x for r in watchers for x in r.get("latency_ms", [])]
    request_ms = [x for r in pollers for x in r["ms"]]
    ended = sum(r.get("end_state") == watched["state"] for r in watchers)
    print(
        f"watched: {watched['n_done']} steps in {watched['wall_s']:.2f} s: "
        f"{watched['steps_per_s']:.2f} steps/s ({watched['state']}) with {n_watch} watchers "
        f"and {n_poll} pollers"
    )
    got = [r.get("distinct", 0) for r in watchers]
    print(
        f"  events: {total} in the run; the watchers got {min(got)}-{max(got)}, lost {lost}, "
        f"streams ended with the run {ended}/{n_watch}"
    )
    print(
        f"  event latency (engine to watcher, last 200 events each): median "
        f"{statistics.median(latencies):.2f} ms, p95 {_percentile(latencies, 0.95):.2f} ms"
    )
    print(
        f"  status requests: {len(request_ms)}, median {statistics.median(request_ms):.2f} ms, "
        f"p95 {_percentile(request_ms, 0.95):.2f} ms, errors {sum(r['errors'] for r in pollers)}"
    )
    return {
        "events_lost": int(lost),
        "steps_per_s_alone": round(alone["steps_per_s"], 3),
        "steps_per_s_watched": round(watched["steps_per_s"], 3),
        "watched_over_alone": round(watched["steps_per_s"] / alone["steps_per_s"], 3),
        "plan": plan,
        "sample_rate_hz": fs,
        "steps": watched["n_done"],
        "run_state_alone": alone["state"],
        "run_state_watched": watched["state"],
        "events_per_run": int(total),
        "watchers": n_watch,
        "watchers_ended_with_run": int(ended),
        "pollers": n_poll,
        "status_requests": len(request_ms),
        "request_errors": int(sum(r["errors"] for r in pollers)),
        "request_ms_median": round(statistics.median(request_ms), 3),
        "request_ms_p95": round(_percentile(request_ms, 0.95), 3),
        "event_latency_ms_median": round(statistics.median(latencies), 3),
        "event_latency_ms_p95": round(_percentile(latencies, 0.95), 3),
    }


if __name__ == "__main__":
    sys.exit(_child_main())
