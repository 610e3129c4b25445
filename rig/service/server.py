"""The acquisition service's HTTP API (aiohttp) and the life of its process.

:func:`serve` is ``python -m rig service start``: it takes the service directory's instance
lock, makes the token on the first start, reads the run records (reporting runs a previous
service left interrupted), starts the rig owner (:mod:`rig.service.worker`: device lock,
backend, amplifier), listens on the loopback address and writes ``endpoint.json``. SIGTERM,
SIGINT and ``POST /api/v1/service/stop`` stop it the same way: the run under way is aborted
through its engine (output ramped to 0 V, completed steps kept) and recorded as interrupted,
the event streams end, the rig is closed, the process exits 0.

Every request must carry ``Authorization: Bearer <token>``: without it the answer is 401,
with a wrong one 403, before anything else is looked at. Request bodies are JSON (at most
1 MiB), plans are data (a built-in plan's name or a plan table, validated like a plan file):
nothing received is unpickled, evaluated or used as a path outside the results folder. The
endpoints are described in ``docs/service-api.md``.
"""

from __future__ import annotations

import asyncio
import fcntl
import ipaddress
import json
import logging
import os
import re
import signal
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from aiohttp import web

from rig.service.auth import bearer_token, ensure_token, token_matches
from rig.service.codec import event_line, to_jsonable
from rig.service.directory import DEFAULT_HOST, DEFAULT_PORT, ServiceDir
from rig.service.hub import EventHub
from rig.service.requests import AbortRequest, RequestError, SubmitRequest, read_request
from rig.service.state import ACTIVE_STATES, FINAL_STATES, RunRecord, RunState, ServiceState
from rig.service.worker import STOP_REASON, RigOptions, RigOwner

__all__ = [
    "HEARTBEAT_S",
    "ServiceOptions",
    "make_app",
    "serve",
]

logger = logging.getLogger(__name__)

API = "/api/v1"
HEARTBEAT_S = 2.0
_BATCH = 256  # event lines per write to a stream
# matched with fullmatch: "$" would also match before a final newline ("ok\n")
_OUT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,119}")


@dataclass(frozen=True)
class ServiceOptions:
    """How ``rig service start`` was asked to run.

    Attributes
    ----------
    backend : {"sim", "ni"}
    setup : str
        Built-in setup name or setup file: the bench every run uses.
    backend_options : mapping
        ``truth``, ``seed``, ``realtime`` for the simulated rig.
    host, port : str, int
        Where to listen (port 0: any free port, written to ``endpoint.json``).
    service_dir : path or None
    results_dir : path or None
        Where measurement files go (default the service directory's ``results``).
    lock_dir : path or None
        Directory of the device locks.
    amplifier_port : str or None
    """

    backend: str = "sim"
    setup: str = "reference"
    backend_options: Mapping[str, Any] = field(default_factory=dict)
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    service_dir: Path | None = None
    results_dir: Path | None = None
    lock_dir: Path | None = None
    amplifier_port: str | None = None


class ApiError(Exception):
    """An answer other than success: HTTP status, short code, message and, for a request or
    plan that does not validate, the key path of the problem."""

    def __init__(
        self, status: int, code: str, message: str, path: tuple[str | int, ...] | None = None
    ) -> None:
        super().__init__(message)
        self.status, self.code, self.message, self.path = status, code, message, path


def _json(data: Any, status: int = 200) -> web.Response:
    return web.Response(
        text=json.dumps(data, allow_nan=False),
        status=status,
        content_type="application/json",
        headers={"Cache-Control": "no-store"},
    )


def _error(
    status: int,
    code: str,
    message: str,
    path: tuple[str | int, ...] | None = None,
    headers: Mapping[str, str] | None = None,
) -> web.Response:
    error: dict[str, Any] = {"status": status, "code": code, "message": message}
    if path is not None:
        error["path"] = list(path)
    resp = _json({"error": error}, status)
    resp.headers.update(headers or {})
    return resp


# ------------------------------------------------------------------------ the application


class Service:
    """State shared by the request handlers (one per process)."""

    def __init__(
        self,
        token: str,
        state: ServiceState,
        hub: EventHub,
        owner: RigOwner,
        setup: Any,
        results_dir: Path,
        info: dict[str, Any],
        request_stop: Callable[[str], None],
    ) -> None:
        self.token = token
        self.state = state
        self.hub = hub
        self.owner = owner
        self.setup = setup
        self.results_dir = results_dir
        self.info = info
        self.request_stop = request_stop

    @property
    def stopping(self) -> bool:
        return self.owner.stopping or self.hub.closing

    def record(self, run_id: str, queued_ok: bool = True) -> RunRecord:
        """The run named in a path; ``current`` is the run under way, else (with
        ``queued_ok``) the next queued one."""
        if run_id == "current":
            record = self.state.current()
            if record is None and queued_ok:
                queued = self.state.queued()
                record = queued[0] if queued else None
            if record is None:
                what = "under way or queued" if queued_ok else "under way"
                raise ApiError(404, "no-current-run", f"no run is {what}")
            return record
        record = self.state.get(run_id)
        if record is None:
            raise ApiError(404, "not-found", f"no run {run_id!r}")
        return record

    def status(self) -> dict[str, Any]:
        with self.state.lock:
            current = self.state.current()
            return {
                "service": {**self.info, "state": "stopping" if self.stopping else "running"},
                "current": current.public() if current else None,
                "queued": [r.id for r in self.state.queued()],
                "interrupted": [r.id for r in self.state.interrupted()],
            }

    def publish_state(self, record: RunRecord) -> None:
        self.hub.publish(
            record.id, RunState(record.state, record.message, record.n_done, record.n_steps)
        )


SERVICE: web.AppKey[Service] = web.AppKey("service", Service)


@web.middleware
async def _guard(request: web.Request, handler) -> web.StreamResponse:
    """Token first, then the handler; every failure becomes a JSON error."""
    service = request.app[SERVICE]
    header = request.headers.get("Authorization")
    if header is not None and not header.isascii():
        # bytes that are not UTF-8 arrive as surrogates; a token is ASCII in any case
        logger.warning(
            "refused %s %s from %s: Authorization header not ASCII",
            request.method,
            request.path,
            request.remote,
        )
        return _error(
            400,
            "bad-token",
            "the Authorization header is not ASCII text: send 'Authorization: Bearer <token>' "
            "with the token exactly as in the service directory's 'token' file",
        )
    given = bearer_token(header)
    if given is None:
        logger.warning(
            "refused %s %s from %s: no token", request.method, request.path, request.remote
        )
        return _error(
            401,
            "no-token",
            "this request carries no token: send 'Authorization: Bearer <token>' (the token "
            "is in the service directory's 'token' file)",
            headers={"WWW-Authenticate": 'Bearer realm="rig-service"'},
        )
    if not token_matches(given, service.token):
        logger.warning(
            "refused %s %s from %s: wrong token", request.method, request.path, request.remote
        )
        return _error(403, "bad-token", "the token is wrong")
    try:
        return await handler(request)
    except ApiError as exc:
        return _error(exc.status, exc.code, exc.message, exc.path)
    except web.HTTPException as exc:
        return _error(exc.status, "http", exc.reason)
    except Exception as exc:
        logger.exception("%s %s failed", request.method, request.path)
        return _error(500, "internal", f"the service failed: {type(exc).__name__}: {exc}")


async def _body(request: web.Request) -> dict[str, Any]:
    if not request.can_read_body:
        return {}
    try:
        data = await request.json()
    except (ValueError, UnicodeDecodeError) as exc:
        raise ApiError(400, "bad-json", f"the body is not valid JSON: {exc}") from None
    except RecursionError:
        raise ApiError(
            400, "bad-json", "the body is nested too deeply (a plan is a few levels deep)"
        ) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ApiError(400, "bad-json", "the body must be a JSON object")
    return data


async def get_service(request: web.Request) -> web.Response:
    return _json(request.app[SERVICE].status())


async def stop_service(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    service.request_stop("a stop request")
    return _json({"stopping": True}, 202)


async def list_runs(request: web.Request) -> web.Response:
    state = request.app[SERVICE].state
    with state.lock:
        return _json({"runs": [r.public() for r in state.runs.values()]})


async def get_run(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    with service.state.lock:
        return _json({"run": service.record(request.match_info["run_id"]).public()})


def _read(cls: type[Any], body: dict[str, Any]) -> Any:
    try:
        return read_request(cls, body)
    except RequestError as exc:
        raise ApiError(400, exc.code, str(exc), exc.error.path) from None


def _plan(spec: Any) -> Any:
    from rig.config.plans import ConfigError, PlanTooLarge, builtin_plans, load_plan, plan_from_dict

    try:
        if isinstance(spec, str):
            names = builtin_plans()
            if spec not in names:
                raise ApiError(
                    400,
                    "bad-plan",
                    f"plan {spec!r} is not a built-in plan (built-in: {', '.join(sorted(names))});"
                    " send a plan file's contents as a table instead",
                )
            return load_plan(spec)
        if isinstance(spec, dict):
            return plan_from_dict(spec, "submitted plan")
    except ValueError as exc:
        # a plan beyond rig.config.plans.MAX_PLAN_STEPS is refused before its steps are listed
        cause: BaseException | None = exc
        while cause is not None and not isinstance(cause, PlanTooLarge):
            cause = cause.__cause__
        code = "bad-plan" if cause is None else "plan-too-large"
        path = ("plan", *exc.path) if isinstance(exc, ConfigError) else None
        raise ApiError(400, code, str(exc), path) from None
    raise ApiError(400, "bad-plan", "'plan' must be a built-in plan's name or a plan table")


def _out_path(service: Service, out: Any, run_id: str, plan_name: str) -> Path:
    if out is None:
        safe = re.sub(r"[^A-Za-z0-9._-]+", "_", plan_name).strip("._") or "run"
        name = f"{run_id}-{safe}.h5"
    else:
        if not isinstance(out, str) or not _OUT_NAME.fullmatch(out):
            raise ApiError(
                400,
                "bad-out",
                "'out' must be a file name (letters, digits, '.', '_', '-'; no folders): "
                "files go to the service's results folder",
            )
        name = out if out.endswith((".h5", ".hdf5")) else f"{out}.h5"
    path = service.results_dir / name
    if path.exists() or str(path) in service.state.paths_in_use():
        raise ApiError(409, "file-exists", f"{path} exists or belongs to another run")
    return path


async def submit_run(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    if service.stopping:
        raise ApiError(503, "stopping", "the service is stopping")
    submit = _read(SubmitRequest, await _body(request))
    plan = _plan(submit.plan)
    try:
        service.setup.channels_for_points(plan.points)
    except ValueError as exc:
        raise ApiError(
            400, "bad-plan", f"plan {plan.name!r} does not fit the bench: {exc}"
        ) from None
    with service.state.lock:
        path = _out_path(service, submit.out, service.state.new_id(), plan.name)
        record = service.state.add(plan, path, submit.label[:200], submit.pause_on_fault)
        logger.info("run %s (%s) queued, %s", record.id, plan.name, path)
    service.publish_state(record)
    return _json({"run": record.public()}, 201)


async def pause_run(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    record = service.record(request.match_info["run_id"], queued_ok=False)
    if not service.owner.pause(record.id):
        raise ApiError(409, "not-running", f"run {record.id} is {record.state}, not under way")
    return _json({"run": record.public()})


async def resume_run(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    record = service.record(request.match_info["run_id"], queued_ok=False)
    if service.owner.resume(record.id):
        return _json({"run": record.public()})
    if record.state in ACTIVE_STATES:
        raise ApiError(409, "queued", f"run {record.id} is queued; it starts in its turn")
    if service.stopping:
        raise ApiError(503, "stopping", "the service is stopping")
    try:
        service.state.requeue(record)
    except ValueError:
        why = "it completed" if record.state == "success" else f"it is {record.state}"
        if record.kind == "random" and record.state != "success":
            why += " and a random test cannot continue an existing file"
        raise ApiError(409, "not-resumable", f"run {record.id} cannot be resumed: {why}") from None
    service.publish_state(record)
    logger.info("run %s queued again to complete %s", record.id, record.path)
    return _json({"run": record.public()})


async def abort_run(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    reason = _read(AbortRequest, await _body(request)).reason or "aborted by the operator"
    record = service.record(request.match_info["run_id"], queued_ok=False)
    if service.owner.abort(reason[:300], record.id):
        return _json({"run": record.public()})
    if record.state != "queued":
        raise ApiError(409, "not-active", f"run {record.id} has ended ({record.state})")
    service.state.cancel(record, reason[:300])
    service.publish_state(record)
    return _json({"run": record.public()})


async def run_result(request: web.Request) -> web.Response:
    from rig.run.session import summarize

    service = request.app[SERVICE]
    record = service.record(request.match_info["run_id"])
    path = Path(record.path)
    summary = None
    if record.state in FINAL_STATES and path.exists():
        try:
            s = await asyncio.to_thread(summarize, path, None, record.plan_name, record.n_steps)
            summary = to_jsonable({k: getattr(s, k) for k in s.__dataclass_fields__})
            summary.update(  # the file does not hold the latest attempt's figures
                written_this_run=record.steps_written,
                wall_s=record.wall_s,
                rig_time_s=record.rig_time_s,
            )
        except (OSError, ValueError, KeyError) as exc:
            summary = {"error": f"cannot read {path}: {exc}"}
    return _json(
        {"run": record.public(), "path": str(path), "exists": path.exists(), "summary": summary}
    )


async def run_events(request: web.Request) -> web.StreamResponse:
    service = request.app[SERVICE]
    record = service.record(request.match_info["run_id"])
    try:
        since = max(0, int(request.query.get("since", "0")))
        follow = request.query.get("follow", "1") not in ("0", "false", "no")
    except ValueError:
        raise ApiError(400, "bad-query", "'since' must be an integer") from None
    log = service.hub.log(record.id)
    resp = web.StreamResponse(
        headers={"Content-Type": "application/x-ndjson", "Cache-Control": "no-store"}
    )
    resp.enable_chunked_encoding()
    await resp.prepare(request)
    pos = min(since, log.last_seq)
    try:
        while True:
            if pos < log.last_seq:
                chunk = log.lines[pos : pos + _BATCH]
                pos += len(chunk)
                await resp.write(b"".join(chunk))
                continue
            if log.final or not follow or service.hub.closing:
                reason = (
                    "service stopped"
                    if service.hub.closing and not log.final
                    else ("run ended" if log.final else "caught up")
                )
                end = {
                    "type": "end",
                    "run": record.id,
                    "seq": pos,
                    "state": record.state,
                    "reason": reason,
                }
                await resp.write(event_line(end))
                break
            if not await log.wait(HEARTBEAT_S):
                await resp.write(event_line({"type": "heartbeat", "run": record.id, "seq": pos}))
    except ConnectionError:
        logger.debug("a watcher of run %s left", record.id)
        return resp
    await resp.write_eof()
    return resp


def make_app(service: Service) -> web.Application:
    """The aiohttp application of the API (routes under ``/api/v1``)."""
    app = web.Application(middlewares=[_guard], client_max_size=1 << 20)
    app[SERVICE] = service
    app.router.add_get(f"{API}/service", get_service)
    app.router.add_post(f"{API}/service/stop", stop_service)
    app.router.add_get(f"{API}/runs", list_runs)
    app.router.add_post(f"{API}/runs", submit_run)
    app.router.add_get(f"{API}/runs/{{run_id}}", get_run)
    app.router.add_post(f"{API}/runs/{{run_id}}/pause", pause_run)
    app.router.add_post(f"{API}/runs/{{run_id}}/resume", resume_run)
    app.router.add_post(f"{API}/runs/{{run_id}}/abort", abort_run)
    app.router.add_get(f"{API}/runs/{{run_id}}/events", run_events)
    app.router.add_get(f"{API}/runs/{{run_id}}/result", run_result)
    return app


# ------------------------------------------------------------------------ the process


def _instance_lock(sdir: ServiceDir) -> int:
    fd = os.open(sdir.lock_path, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.lseek(fd, 0, os.SEEK_SET)
        pid = os.read(fd, 32).decode("ascii", "replace").strip() or "unknown"
        os.close(fd)
        raise RuntimeError(
            f"an acquisition service already runs for {sdir.root} (process {pid}); "
            "'rig service status' shows it, 'rig service stop' stops it"
        ) from None
    os.ftruncate(fd, 0)
    os.write(fd, str(os.getpid()).encode("ascii"))
    return fd


def _count_steps_on_disk(state: ServiceState) -> None:
    """Steps in the files of interrupted runs (a killed service could not record the last)."""
    from analysis.measurement_file import read_measurement

    for r in state.interrupted():
        if r.kind != "stepped-sine" or not Path(r.path).exists():
            continue
        try:
            r.n_done = int(read_measurement(r.path).n_steps)
        except (OSError, ValueError, KeyError) as exc:
            logger.warning("run %s: cannot read %s: %s", r.id, r.path, exc)
    state.save()


def serve(options: ServiceOptions, out: TextIO | None = None) -> int:
    """Run the service until it is stopped; return the exit status (0 after a clean stop).

    Parameters
    ----------
    options : ServiceOptions
    out : text stream
        Where the start-up report goes (default stdout): address, token file, runs a
        previous service left interrupted.

    Raises
    ------
    RuntimeError, OSError, ValueError
        If the service cannot start (another one runs for the directory, the device is in
        use, the port is taken, the setup is invalid); nothing is left running.
    """
    from rig.config.setup import load_setup

    out = out or sys.stdout
    sdir = ServiceDir(options.service_dir)
    sdir.create()
    lock_fd = _instance_lock(sdir)
    try:
        setup = load_setup(options.setup)
        token, created = ensure_token(sdir.token_path)
        state = ServiceState.load(sdir.state_path)
        _count_steps_on_disk(state)
        results = Path(options.results_dir or sdir.results_dir).expanduser().resolve()
        results.mkdir(parents=True, exist_ok=True)
        return asyncio.run(_main(options, sdir, setup, token, created, state, results, out))
    finally:
        os.close(lock_fd)


async def _main(
    options: ServiceOptions,
    sdir: ServiceDir,
    setup: Any,
    token: str,
    token_created: bool,
    state: ServiceState,
    results: Path,
    out: TextIO,
) -> int:
    loop = asyncio.get_running_loop()
    hub = EventHub(sdir.events_dir, state, loop)
    backend_options = dict(options.backend_options)
    if options.backend == "sim":
        backend_options.setdefault("sensor_masses_kg", setup.sensor_masses_kg())
    shown_options = {k: v for k, v in backend_options.items() if k != "sensor_masses_kg"}
    stop = asyncio.Event()
    reason: list[str] = []

    def request_stop(why: str) -> None:
        if not reason:
            reason.append(why)
            logger.info("stopping (%s)", why)
        owner.stop()  # at once: new submissions are refused, the run under way ends
        loop.call_soon_threadsafe(stop.set)

    def owner_ended() -> None:
        request_stop(f"the rig owner ended: {owner.error!r}")

    owner = RigOwner(
        RigOptions(
            options.backend, setup, backend_options, options.lock_dir, options.amplifier_port
        ),
        state,
        hub.publish_threadsafe,
        {"backend": options.backend, "backend_options": to_jsonable(shown_options)},
        on_exit=owner_ended,
    )
    owner.start()
    await asyncio.to_thread(owner.ready.wait)
    if owner.error is not None:
        owner.join(10.0)
        raise owner.error

    info = {
        "pid": os.getpid(),
        "backend": options.backend,
        "backend_options": to_jsonable(shown_options),
        "setup": setup.name,
        "sample_rate_hz": setup.daq.sample_rate_hz,
        "service_dir": str(sdir.root),
        "results_dir": str(results),
        "started_s": time.time(),
    }
    service = Service(token, state, hub, owner, setup, results, info, request_stop)
    runner = web.AppRunner(make_app(service), access_log=None, handle_signals=False)
    await runner.setup()
    try:
        site = web.TCPSite(runner, options.host, options.port, shutdown_timeout=5.0)
        await site.start()
    except BaseException:
        await runner.cleanup()
        owner.stop()
        await asyncio.to_thread(owner.join, 60.0)
        raise
    host, port = runner.addresses[0][:2]
    info.update(host=host, port=port)
    if not _loopback(options.host):
        logger.warning(
            "listening on %s, not only on this computer: whoever reaches it with the token "
            "controls the rig, and the traffic is not encrypted",
            options.host,
        )
    sdir.write_endpoint(info)
    for sig, name in ((signal.SIGTERM, "SIGTERM"), (signal.SIGINT, "SIGINT")):
        loop.add_signal_handler(sig, request_stop, name)
    _announce(out, info, sdir, token_created, state)
    try:
        await stop.wait()
    finally:
        status = await _shutdown(owner, hub, runner, sdir, reason[0] if reason else "")
    return status if owner.error is None else 1


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _announce(
    out: TextIO, info: dict[str, Any], sdir: ServiceDir, token_created: bool, state: ServiceState
) -> None:
    lines = [
        f"rig service listening on http://{info['host']}:{info['port']} (process {info['pid']}, "
        f"{info['backend']} backend, setup {info['setup']})",
        f"token file {sdir.token_path}" + (" (new)" if token_created else ""),
        f"results in {info['results_dir']}",
    ]
    interrupted = state.interrupted()
    if interrupted:
        lines.append(f"{len(interrupted)} interrupted run(s) from before:")
        for r in interrupted:
            how = "resume with: rig resume " + r.id if r.resumable else "cannot be resumed"
            lines.append(
                f"  {r.id} {r.plan_name}: {r.n_done}/{r.n_steps} steps, {r.message}; {how}"
            )
    out.write("\n".join(lines) + "\n")
    out.flush()
    for line in lines[3:]:
        logger.info("%s", line.strip())


async def _shutdown(
    owner: RigOwner, hub: EventHub, runner: web.AppRunner, sdir: ServiceDir, why: str
) -> int:
    logger.warning("the service stops (%s): %s", why or "stop", STOP_REASON)
    owner.stop()
    status = 0
    await asyncio.to_thread(owner.join, 120.0)
    if owner.is_alive():
        logger.error("the run did not end within 120 s of the stop request; exiting anyway")
        status = 1
    await asyncio.sleep(0)  # let the last events of the run reach the logs
    hub.close()
    sdir.remove_endpoint(os.getpid())
    await runner.cleanup()
    return status
