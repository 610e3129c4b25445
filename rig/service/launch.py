"""Starting a service in the background, for ``rig service start --detach``, the GUI and scripts.

::

    from rig.service.launch import ensure_service

    client = ensure_service(backend="sim")   # the running service, or a new one on the sim rig

The service runs as ``python -m rig service start ...`` in a session of its own (closing the
terminal or the GUI that started it does not stop it), with its output appended to the
service directory's ``service.log``. Only the standard library is used here.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from rig.service.client import ServiceClient, ServiceError, ServiceUnavailable
from rig.service.directory import DEFAULT_HOST, DEFAULT_PORT, ServiceDir

__all__ = ["ensure_service", "service_command", "start_service"]


def service_command(
    service_dir: str | os.PathLike[str] | None = None,
    *,
    backend: str = "sim",
    setup: str | os.PathLike[str] = "reference",
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    truth: str | None = None,
    seed: int | None = None,
    realtime: bool = False,
    results_dir: str | os.PathLike[str] | None = None,
    lock_dir: str | os.PathLike[str] | None = None,
    amplifier_port: str | None = None,
    verbose: bool = False,
) -> list[str]:
    """The command line of a foreground service with these options."""
    argv = [sys.executable, "-m", "rig"] + (["--verbose"] if verbose else [])
    argv += ["service", "start", "--backend", backend, "--setup", str(setup)]
    argv += ["--host", host, "--port", str(port)]
    for flag, value in (
        ("--service-dir", service_dir),
        ("--truth", truth),
        ("--seed", seed),
        ("--results-dir", results_dir),
        ("--lock-dir", lock_dir),
        ("--amplifier-port", amplifier_port),
    ):
        if value is not None:
            argv += [flag, str(value)]
    if realtime:
        argv.append("--realtime")
    return argv


def start_service(
    service_dir: str | os.PathLike[str] | None = None,
    *,
    timeout_s: float = 60.0,
    **options: Any,
) -> dict[str, Any]:
    """Start a service in the background and wait until it listens.

    Parameters
    ----------
    service_dir : path, optional
        Its directory (default :func:`rig.service.directory.default_service_dir`).
    timeout_s : float
        How long to wait for it to listen [s].
    **options
        As :func:`service_command` (``backend``, ``setup``, ``truth``, ``port``, ...).

    Returns
    -------
    dict
        Its ``endpoint.json`` (``host``, ``port``, ``pid``, ...).

    Raises
    ------
    RuntimeError
        If it exits before it listens (the message ends with its log) or does not answer in
        time.
    """
    sdir = ServiceDir(service_dir)
    sdir.create()
    argv = service_command(sdir.root, **options)
    fd = os.open(sdir.log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    with os.fdopen(fd, "ab") as log:
        child = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=log, stderr=log, start_new_session=True
        )
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if child.poll() is not None:
            tail = _tail(sdir.log_path)
            raise RuntimeError(f"the acquisition service did not start:\n{tail}")
        info = sdir.read_endpoint()
        if info is not None and info.get("pid") == child.pid:
            return info
        time.sleep(0.1)
    raise RuntimeError(
        f"the acquisition service (process {child.pid}) did not listen within {timeout_s:g} s; "
        f"see {sdir.log_path}"
    )


def ensure_service(
    service_dir: str | os.PathLike[str] | None = None,
    *,
    timeout_s: float = 60.0,
    **options: Any,
) -> ServiceClient:
    """A client of the service of ``service_dir``, started first if none answers there.

    The options (:func:`service_command`) apply only to a service started here; a running
    service is used as it is (its ``status()["service"]`` says which backend it owns).
    """
    try:
        client = ServiceClient.connect(service_dir)
        client.status()
        return client
    except ServiceUnavailable:
        pass
    except ServiceError as exc:
        if exc.status:  # it answered: a token problem is not solved by starting another
            raise
    start_service(service_dir, timeout_s=timeout_s, **options)
    return ServiceClient.connect(service_dir)


def _tail(path: Path, n: int = 8) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"
