"""The acquisition service as a user runs it: real processes on real loopback sockets.

``service_factory`` starts ``python -m rig service start --backend sim`` in the foreground (a
child process) on a free port with a temporary service directory and lock directory, and
waits until it has written its endpoint; every process it or a test starts through
:class:`Procs` is ended when the test (or module) ends, and the teardown fails if one had to be
killed. The bench is the reference setup at 5120 Hz with a cut paper plan (``paper_cut.toml``:
the paper's settings and limits, 60 steps), long enough to pause, stop and kill mid-run.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import tomli_w

from rig.config.plans import load_plan
from rig.config.setup import load_setup
from rig.service.client import ServiceClient

ENV = {
    k: v
    for k, v in os.environ.items()
    if k not in ("RIG_SERVICE_DIR", "RIG_SERVICE_URL", "RIG_SERVICE_TOKEN", "RIG_LOCK_DIR")
}
ENV["OMP_NUM_THREADS"] = "1"
FS_TEST = 5120.0
#: The cut paper plan's steps: 21-40 Hz in 1 Hz steps at 2, 4 and 8 N.
CUT_STEPS = 60


class Procs:
    """Child processes of a test; :meth:`cleanup` ends those still running."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []
        self.pids: list[int] = []  # processes not started here (a detached service)

    def popen(self, args, **kwargs) -> subprocess.Popen:
        kwargs.setdefault("env", ENV)
        proc = subprocess.Popen([sys.executable, "-m", "rig", *map(str, args)], **kwargs)
        self.procs.append(proc)
        return proc

    def cleanup(self) -> list[str]:
        """End every child still alive (SIGTERM, then SIGKILL); returns what had to be ended."""
        left = []
        for proc in self.procs:
            if proc.poll() is None:
                left.append(" ".join(map(str, proc.args[3:6])))
                proc.terminate()
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(10)
        for pid in self.pids:
            if _alive(pid):
                left.append(f"process {pid}")
                os.kill(pid, signal.SIGTERM)
                deadline = time.monotonic() + 20
                while _alive(pid) and time.monotonic() < deadline:
                    time.sleep(0.1)
                if _alive(pid):
                    os.kill(pid, signal.SIGKILL)
        return left


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie child of ours counts as gone
        done, _ = os.waitpid(pid, os.WNOHANG)
        return done == 0
    except ChildProcessError:
        return True


def rig(*args, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """Run ``python -m rig ARGS`` to completion."""
    return subprocess.run(
        [sys.executable, "-m", "rig", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=ENV,
    )


def wait_for(predicate, timeout_s: float, what: str, poll_s: float = 0.05):
    """Poll ``predicate()`` until it returns something true; fail after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(poll_s)


class ServiceProcess:
    """A service started in the foreground as a child process."""

    def __init__(self, procs: Procs, sdir: Path, bench: Path) -> None:
        self.procs = procs
        self.sdir = sdir
        self.bench = bench
        self.proc: subprocess.Popen | None = None
        self.stdout_path = sdir.parent / f"{sdir.name}.stdout"
        self.lock_dir = sdir.parent / f"{sdir.name}-locks"  # each service owns its own device

    def start(self, timeout_s: float = 60.0) -> ServiceProcess:
        out = open(self.stdout_path, "w")  # noqa: SIM115 - the child writes to it
        self.proc = self.procs.popen(
            [
                "service",
                "start",
                "--backend",
                "sim",
                "--setup",
                self.bench / "setup.toml",
                "--service-dir",
                self.sdir,
                "--port",
                0,
                "--lock-dir",
                self.lock_dir,
            ],
            stdout=out,
            stderr=subprocess.STDOUT,
        )
        out.close()

        def ready():
            if self.proc.poll() is not None:
                raise AssertionError(f"the service exited:\n{self.output()}")
            path = self.sdir / "endpoint.json"
            try:
                info = json.loads(path.read_text())
            except (OSError, ValueError):
                return None
            return info.get("pid") == self.proc.pid

        wait_for(ready, timeout_s, "the service to listen")
        return self

    def output(self) -> str:
        return self.stdout_path.read_text()

    def client(self, **kwargs) -> ServiceClient:
        return ServiceClient.connect(self.sdir, **kwargs)

    def cli(self, *args, timeout: float = 60.0) -> subprocess.CompletedProcess:
        return rig(*args, "--service-dir", self.sdir, timeout=timeout)

    def wait_exit(self, timeout_s: float = 60.0) -> int:
        return self.proc.wait(timeout_s)


@pytest.fixture(scope="session")
def bench(tmp_path_factory) -> Path:
    """A folder with the bench: the reference setup at 5120 Hz, its impedance head's
    accelerometer at 10 mV/g (the 100 mV/g one clips near the contact resonance at 8 N when a
    resumed run's controller takes another path there), and the paper plan cut to
    :data:`CUT_STEPS` steps through the contact (``paper_cut.toml``)."""
    d = tmp_path_factory.mktemp("bench")
    setup = load_setup("reference").with_sample_rate(FS_TEST).to_dict()
    acc3 = next(c for c in setup["channels"] if c["name"] == "acc3")
    acc3["sensitivity"] = 10.13
    (d / "setup.toml").write_bytes(tomli_w.dumps(setup).encode())
    plan = load_plan("paper").to_dict()
    plan["name"] = "paper_cut"
    plan["excitation"]["levels_n"] = [2.0, 4.0, 8.0]
    plan["frequencies"]["ranges"] = [{"start_hz": 21.0, "stop_hz": 40.0, "step_hz": 1.0}]
    (d / "paper_cut.toml").write_bytes(tomli_w.dumps(plan).encode())
    return d


def _factory(procs: Procs, base: Path, bench: Path):
    def make(name: str = "service") -> ServiceProcess:
        return ServiceProcess(procs, base / name, bench)

    return make


@pytest.fixture
def procs():
    p = Procs()
    yield p
    left = p.cleanup()
    assert not left, f"processes still running after the test: {left}"


@pytest.fixture
def service_factory(procs, tmp_path, bench):
    """Make (not start) services with their own directories under the test's tmp_path."""
    return _factory(procs, tmp_path, bench)


@pytest.fixture(scope="module")
def module_procs():
    p = Procs()
    yield p
    left = p.cleanup()
    assert not left, f"processes still running after the module: {left}"


@pytest.fixture(scope="module")
def shared_service(module_procs, tmp_path_factory, bench) -> ServiceProcess:
    """One service for a module's tests (stopped by SIGTERM at the end)."""
    svc = _factory(module_procs, tmp_path_factory.mktemp("shared"), bench)().start()
    yield svc
    if svc.proc.poll() is None:
        svc.proc.send_signal(signal.SIGTERM)
        assert svc.proc.wait(60) == 0, svc.output()
