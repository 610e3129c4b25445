"""The service directory: where the acquisition service keeps its token, address and state.

One directory per service (one per rig). First that applies: the ``--service-dir`` option, the
``RIG_SERVICE_DIR`` environment variable, ``$XDG_STATE_HOME/clearance-rig/service``,
``~/.local/state/clearance-rig/service``. The directory is created user-only (0700) and
holds:

``token``
    The access token (0600), made on the first start (:mod:`rig.service.auth`).
``endpoint.json``
    Address and PID of the running service (0600); removed when it stops. Clients read it to
    find the service.
``state.json``
    Run records and the queue (:mod:`rig.service.state`), rewritten atomically.
``events/<run>.ndjson``
    Every event of a run, one JSON object a line, as the event stream sends them.
``results/``
    Measurement files (unless the service is started with ``--results-dir``).
``service.lock``
    Held by the running service: one service per directory.
``service.log``
    Output of a service started with ``rig service start --detach``.

Only the standard library is used here: clients import this module too.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

__all__ = [
    "DEFAULT_HOST",
    "DEFAULT_PORT",
    "SERVICE_DIR_ENV",
    "TOKEN_ENV",
    "URL_ENV",
    "ServiceDir",
    "default_service_dir",
    "write_private",
]

SERVICE_DIR_ENV = "RIG_SERVICE_DIR"
URL_ENV = "RIG_SERVICE_URL"
TOKEN_ENV = "RIG_SERVICE_TOKEN"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 7412


def default_service_dir() -> Path:
    """The service directory unless told otherwise (see the module notes)."""
    env = os.environ.get(SERVICE_DIR_ENV)
    if env:
        return Path(env).expanduser()
    state = os.environ.get("XDG_STATE_HOME")
    base = Path(state).expanduser() if state else Path.home() / ".local" / "state"
    return base / "clearance-rig" / "service"


def write_private(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically, readable and writable by the owner only (0600)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.fchmod(fd, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


class ServiceDir:
    """Paths of a service directory.

    Parameters
    ----------
    root : path, optional
        The directory (default :func:`default_service_dir`).
    """

    def __init__(self, root: str | os.PathLike[str] | None = None) -> None:
        self.root = (
            Path(root).expanduser() if root is not None else default_service_dir()
        ).absolute()

    def __repr__(self) -> str:
        return f"ServiceDir({str(self.root)!r})"

    @property
    def token_path(self) -> Path:
        return self.root / "token"

    @property
    def endpoint_path(self) -> Path:
        return self.root / "endpoint.json"

    @property
    def state_path(self) -> Path:
        return self.root / "state.json"

    @property
    def events_dir(self) -> Path:
        return self.root / "events"

    @property
    def results_dir(self) -> Path:
        return self.root / "results"

    @property
    def lock_path(self) -> Path:
        return self.root / "service.lock"

    @property
    def log_path(self) -> Path:
        return self.root / "service.log"

    def create(self) -> None:
        """Create the directory (user-only, 0700) and its ``events`` folder."""
        self.root.mkdir(parents=True, exist_ok=True)
        os.chmod(self.root, 0o700)
        self.events_dir.mkdir(exist_ok=True)
        os.chmod(self.events_dir, 0o700)

    def read_endpoint(self) -> dict[str, Any] | None:
        """What the running service wrote (``host``, ``port``, ``pid``, ...), or None."""
        try:
            data = json.loads(self.endpoint_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return data if isinstance(data, dict) else None

    def write_endpoint(self, info: dict[str, Any]) -> None:
        write_private(self.endpoint_path, json.dumps(info, indent=1))

    def remove_endpoint(self, pid: int) -> None:
        """Remove the endpoint file if it is the one process ``pid`` wrote."""
        info = self.read_endpoint()
        if info is not None and info.get("pid") == pid:
            try:
                self.endpoint_path.unlink()
            except OSError:
                pass
