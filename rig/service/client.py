"""Client of the acquisition service, for the GUI and for scripts (standard library only).

::

    from rig.service.client import ServiceClient

    client = ServiceClient.connect()            # address and token from the service directory
    run_id = client.submit("quick")             # built-in plan name, plan file, Plan or dict
    with client.events(run_id) as stream:       # every event of the run, in order
        for event in stream:
            if event["type"] == "StepFinished":
                print(event["data"]["n_done"], "steps on disk")
    print(client.result(run_id)["path"])

Every method is one HTTP request on its own connection, so one client may be used from several
threads (a GUI reads an event stream in a worker thread and pauses from its own). Errors are
:class:`ServiceError` (with the HTTP status), :class:`ServiceUnavailable` when nothing answers
and :class:`AuthenticationError` when the token is missing or wrong. The API itself is
described in ``docs/service-api.md``.

Events are dicts ``{"seq", "run", "type", "time_s", "data"}``: ``seq`` counts the run's events
from 1 without gaps, ``type`` is the event class (:mod:`rig.run.events`: ``StepFinished``,
``ControlIteration``, ``FaultRaised``, ...) or ``RunState`` (the service's own: queued, running,
paused, and how the run ended), ``data`` the event's fields with arrays as lists and complex
numbers as ``[re, im]`` pairs (:mod:`rig.service.codec`).
"""

from __future__ import annotations

import http.client
import json
import os
import socket
import threading
import time
import tomllib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import quote, urlencode, urlsplit

from rig.service.auth import read_token
from rig.service.directory import TOKEN_ENV, URL_ENV, ServiceDir

__all__ = [
    "FINAL_STATES",
    "AuthenticationError",
    "EventStream",
    "ServiceClient",
    "ServiceError",
    "ServiceUnavailable",
]

API = "/api/v1"
FINAL_STATES = frozenset({"success", "aborted", "failed", "interrupted", "cancelled"})
"""Run states after which a run does nothing more (until it is resumed)."""


class ServiceError(RuntimeError):
    """A request to the service failed.

    Attributes
    ----------
    status : int
        HTTP status (0 when no answer came).
    code : str
        Short machine-readable reason from the service (``"not-found"``, ``"conflict"``, ...).
    """

    def __init__(self, message: str, status: int = 0, code: str = "") -> None:
        super().__init__(message)
        self.status = status
        self.code = code


class ServiceUnavailable(ServiceError):
    """No service answers at the address (not started, stopped, or the address is wrong)."""


class AuthenticationError(ServiceError):
    """The service refused the request: token missing (401) or wrong (403)."""


def _describe(host: str, port: int) -> str:
    return f"http://{host}:{port}"


class EventStream:
    """The events of one run, as they happen; iterate it, close it from any thread.

    Created by :meth:`ServiceClient.events`. Iteration yields event dicts in ``seq`` order and
    stops when the run has ended (its final ``RunState`` event was delivered), when the service
    stops, or after :meth:`close`.

    Attributes
    ----------
    run_id : str
    last_seq : int
        ``seq`` of the last event delivered (``since`` to continue after a reconnection).
    lost : int
        Events missing between those delivered (0 unless the stream skipped some).
    end : dict or None
        The service's closing message (``{"type": "end", "state": ..., "reason": ...}``) once
        the stream has ended normally.
    """

    def __init__(
        self, conn: http.client.HTTPConnection, resp: http.client.HTTPResponse, run_id: str
    ) -> None:
        self._conn = conn
        self._resp = resp
        self.run_id = run_id
        self.last_seq: int | None = None
        self.lost = 0
        self.end: dict[str, Any] | None = None
        self._closed = threading.Event()

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return self

    def __next__(self) -> dict[str, Any]:
        while True:
            if self._closed.is_set() or self.end is not None:
                raise StopIteration
            try:
                line = self._resp.readline()
            except (OSError, ValueError, http.client.HTTPException) as exc:
                if self._closed.is_set():
                    raise StopIteration from None
                self.close()
                raise ServiceError(f"event stream of run {self.run_id} broke: {exc}") from exc
            if not line:
                closed = self._closed.is_set()
                self.close()
                if closed:
                    raise StopIteration
                raise ServiceError(
                    f"event stream of run {self.run_id} ended before the run did "
                    "(the service went away)"
                )
            line = line.strip()
            if not line:
                continue
            event = json.loads(line)
            kind = event.get("type")
            if kind == "heartbeat":
                continue
            if kind == "end":
                self.end = event
                self.close()
                raise StopIteration
            seq = int(event["seq"])
            if self.last_seq is not None and seq > self.last_seq + 1:
                self.lost += seq - self.last_seq - 1
            self.last_seq = seq
            return event

    def close(self) -> None:
        """End the stream (safe from another thread; a blocked iteration returns)."""
        first = not self._closed.is_set()
        self._closed.set()
        if not first:
            return
        sock = getattr(self._conn, "sock", None)
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self._conn.close()

    def __enter__(self) -> EventStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ServiceClient:
    """Talks to a running acquisition service.

    Parameters
    ----------
    host : str
        Address of the service (default the loopback address).
    port : int
    token : str
        The service's access token (its directory's ``token`` file).
    timeout_s : float
        Timeout of a request [s] (an event stream waits up to ``stream_timeout_s`` for a line;
        the service sends a heartbeat every 2 s).
    stream_timeout_s : float

    See Also
    --------
    ServiceClient.connect : address and token from the service directory.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 7412,
        token: str = "",
        *,
        timeout_s: float = 10.0,
        stream_timeout_s: float = 30.0,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.token = token
        self.timeout_s = float(timeout_s)
        self.stream_timeout_s = float(stream_timeout_s)

    @classmethod
    def connect(
        cls,
        service_dir: str | os.PathLike[str] | None = None,
        *,
        url: str | None = None,
        token: str | None = None,
        timeout_s: float = 10.0,
    ) -> ServiceClient:
        """A client for the service of a service directory.

        The address is, first that applies: ``url``, ``$RIG_SERVICE_URL``, the directory's
        ``endpoint.json`` (written by the running service); the token: ``token``,
        ``$RIG_SERVICE_TOKEN``, the directory's ``token`` file.

        Raises
        ------
        ServiceUnavailable
            If no address is known (no service has started in that directory, or it stopped).
        AuthenticationError
            If no token can be found.
        """
        sdir = ServiceDir(service_dir)
        url = url or os.environ.get(URL_ENV)
        if url:
            parts = urlsplit(url if "//" in url else f"http://{url}")
            if parts.scheme not in ("http", "") or not parts.hostname:
                raise ValueError(f"service URL {url!r}: expected http://HOST:PORT")
            host, port = parts.hostname, parts.port or 7412
        else:
            info = sdir.read_endpoint()
            if info is None:
                raise ServiceUnavailable(
                    f"no acquisition service is running for {sdir.root} (no endpoint.json); "
                    "start one: python -m rig service start --backend sim"
                )
            host, port = str(info["host"]), int(info["port"])
            if host in ("0.0.0.0", "::", ""):
                host = "127.0.0.1"
        token = token or os.environ.get(TOKEN_ENV) or read_token(sdir.token_path)
        if not token:
            raise AuthenticationError(
                f"no access token: {sdir.token_path} is missing or unreadable (set "
                f"{TOKEN_ENV} to use a service elsewhere)",
                401,
                "no-token",
            )
        return cls(host, port, token, timeout_s=timeout_s)

    @property
    def url(self) -> str:
        return _describe(self.host, self.port)

    def __repr__(self) -> str:
        return f"ServiceClient({self.url!r})"

    # ------------------------------------------------------------------ HTTP
    def _headers(self, body: bool) -> dict[str, str]:
        headers = {"Accept": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        if body:
            headers["Content-Type"] = "application/json"
        return headers

    def _open(
        self, method: str, path: str, body: Any = None, timeout_s: float | None = None
    ) -> tuple[http.client.HTTPConnection, http.client.HTTPResponse]:
        data = None if body is None else json.dumps(body).encode("utf-8")
        conn = http.client.HTTPConnection(self.host, self.port, timeout=timeout_s or self.timeout_s)
        try:
            conn.request(method, API + path, body=data, headers=self._headers(data is not None))
            resp = conn.getresponse()
        except ConnectionRefusedError as exc:
            conn.close()
            raise ServiceUnavailable(f"no acquisition service answers at {self.url}") from exc
        except (OSError, http.client.HTTPException) as exc:
            conn.close()
            raise ServiceError(f"{method} {self.url}{API}{path} failed: {exc}") from exc
        if resp.status >= 400:
            try:
                raw = resp.read()
            finally:
                conn.close()
            _raise_for(resp.status, raw, method, path)
        return conn, resp

    def _request(self, method: str, path: str, body: Any = None) -> dict[str, Any]:
        conn, resp = self._open(method, path, body)
        try:
            raw = resp.read()
        except (OSError, http.client.HTTPException) as exc:
            raise ServiceError(
                f"{method} {self.url}{API}{path}: no complete answer: {exc}"
            ) from exc
        finally:
            conn.close()
        return json.loads(raw) if raw else {}

    # ------------------------------------------------------------------ the service
    def status(self) -> dict[str, Any]:
        """The service, the current run and the queue.

        Returns
        -------
        dict
            ``{"service": {...}, "current": run or None, "queued": [ids],
            "interrupted": [ids]}`` (runs as in :meth:`run`).
        """
        return self._request("GET", "/service")

    def stop_service(self) -> dict[str, Any]:
        """Ask the service to stop: the current run is ended (output ramped to 0 V, completed
        steps kept) and recorded as interrupted, then the process exits."""
        return self._request("POST", "/service/stop", {})

    # ------------------------------------------------------------------ runs
    def submit(
        self,
        plan: Any,
        *,
        out: str | None = None,
        label: str = "",
        pause_on_fault: bool = False,
    ) -> str:
        """Queue a run; returns its id.

        Parameters
        ----------
        plan : str, path, Plan or mapping
            A built-in plan name (``"paper"``, ``"quick"``, ``"linear"``), a plan file (read
            here and sent as data), a :class:`rig.config.plans.SteppedSinePlan` /
            :class:`rig.config.plans.RandomPlan`, or a plan table as a mapping.
        out : str, optional
            File name of the measurement file in the service's results folder (default
            ``<run id>-<plan>.h5``).
        label : str
            Free text shown in run lists.
        pause_on_fault : bool
            Recoverable faults (clipping, a silent sensor, no force, an amplifier overload)
            pause the run instead of ending it; :meth:`resume` continues it.

        Raises
        ------
        ServiceError
            Status 400 if the plan is invalid (the message names the key), 409 if the file
            exists, 503 if the service is stopping.
        """
        body: dict[str, Any] = {"plan": _plan_payload(plan)}
        if out:
            body["out"] = str(out)
        if label:
            body["label"] = str(label)
        if pause_on_fault:
            body["pause_on_fault"] = True
        return str(self._request("POST", "/runs", body)["run"]["id"])

    def runs(self) -> list[dict[str, Any]]:
        """Every run the service knows, oldest first (see :meth:`run` for the fields)."""
        return list(self._request("GET", "/runs")["runs"])

    def run(self, run_id: str = "current") -> dict[str, Any]:
        """One run's record.

        Returns
        -------
        dict
            ``id, plan, kind, label, state, message, n_steps, n_done, path, events,
            submitted_s, started_s, finished_s, attempts, steps_written, wall_s, rig_time_s,
            pause_on_fault, resumable``; ``state`` is one of ``queued, running, paused,
            success, aborted, failed, interrupted, cancelled`` (``docs/service-api.md``).
        """
        return self._request("GET", f"/runs/{_q(run_id)}")["run"]

    def pause(self, run_id: str | None = None) -> dict[str, Any]:
        """Pause the running run (default the current one): the output ramps to 0 V at the next
        block and the run waits. Returns its record."""
        return self._request("POST", f"/runs/{_q(run_id)}/pause", {})["run"]

    def resume(self, run_id: str | None = None) -> dict[str, Any]:
        """Continue a run: a paused run goes on; an interrupted, aborted or failed stepped-sine
        run is queued again and completes its file. Returns its record."""
        return self._request("POST", f"/runs/{_q(run_id)}/resume", {})["run"]

    def abort(self, run_id: str | None = None, reason: str = "") -> dict[str, Any]:
        """End a run (default the current one): a running run ramps down and keeps its steps;
        a queued run is cancelled. Returns its record."""
        body = {"reason": reason} if reason else {}
        return self._request("POST", f"/runs/{_q(run_id)}/abort", body)["run"]

    def result(self, run_id: str) -> dict[str, Any]:
        """Where a run's measurement file is and what is in it.

        Returns
        -------
        dict
            ``{"run": record, "path": str, "exists": bool, "summary": dict or None}``; the
            summary (as ``rig run --json`` prints it) once the run has ended.
        """
        return self._request("GET", f"/runs/{_q(run_id)}/result")

    def events(
        self,
        run_id: str | None = None,
        since: int = 0,
        *,
        follow: bool = True,
    ) -> EventStream:
        """Stream a run's events with ``seq`` greater than ``since``.

        Parameters
        ----------
        run_id : str, optional
            Default the current run (or, if none runs, the next queued one).
        since : int
            Last ``seq`` already seen (0: from the start).
        follow : bool
            Keep the stream open until the run ends (False: what is there now, then stop).
        """
        query = urlencode({"since": int(since), "follow": int(bool(follow))})
        path = f"/runs/{_q(run_id)}/events?{query}"
        conn, resp = self._open("GET", path, timeout_s=self.stream_timeout_s)
        return EventStream(conn, resp, run_id or "current")

    def wait(self, run_id: str, timeout_s: float = 3600.0, poll_s: float = 0.2) -> dict[str, Any]:
        """Block until the run reaches a final state; return its record.

        Raises
        ------
        TimeoutError
            If it has not ended within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            record = self.run(run_id)
            if record["state"] in FINAL_STATES:
                return record
            if time.monotonic() > deadline:
                raise TimeoutError(f"run {run_id} still {record['state']} after {timeout_s} s")
            time.sleep(poll_s)


def _q(run_id: str | None) -> str:
    return quote(str(run_id or "current"), safe="")


def _plan_payload(plan: Any) -> Any:
    if hasattr(plan, "to_dict") and hasattr(plan, "kind"):
        return plan.to_dict()
    if isinstance(plan, Mapping):
        return dict(plan)
    if isinstance(plan, os.PathLike) or (
        isinstance(plan, str) and (plan.endswith(".toml") or os.sep in plan or Path(plan).is_file())
    ):
        path = Path(plan)
        try:
            with open(path, "rb") as fh:
                return tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"plan file {path}: not valid TOML: {exc}") from exc
    if isinstance(plan, str) and plan:
        return plan
    raise TypeError(f"submit: expected a plan name, plan file, Plan or mapping, got {plan!r}")


def _raise_for(status: int, raw: bytes, method: str, path: str) -> None:
    try:
        err = json.loads(raw).get("error", {})
        message, code = str(err.get("message", "")), str(err.get("code", ""))
    except (ValueError, AttributeError):
        message, code = raw.decode("utf-8", "replace")[:200], ""
    message = message or f"{method} {API}{path}: HTTP {status}"
    if status in (401, 403):
        raise AuthenticationError(message, status, code)
    if status == 503:
        raise ServiceUnavailable(message, status, code)
    raise ServiceError(message, status, code)
