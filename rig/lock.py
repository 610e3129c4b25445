"""One process at a time owns a device: an OS-level lock file per device name.

The command line, the GUI and the acquisition service all take :class:`DeviceLock` before they
open a DAQ device, so two programs never drive the same shaker. The lock is ``fcntl.flock`` on
``<lock_dir>/<device>.lock``: the operating system releases it when the owner exits, however it
exits (a crash or ``kill -9`` leaves no stale lock). The file holds the owner's PID, command
line and start time, which a second would-be owner sees in its error message.

Lock directory, first that applies: the ``lock_dir`` argument, the ``RIG_LOCK_DIR`` environment
variable, ``$XDG_RUNTIME_DIR/clearance-rig``, ``~/.cache/clearance-rig/locks``.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import re
import sys
import time
from pathlib import Path
from types import TracebackType

__all__ = ["DeviceBusyError", "DeviceLock", "default_lock_dir", "lock_holder"]

logger = logging.getLogger(__name__)

LOCK_DIR_ENV = "RIG_LOCK_DIR"


class DeviceBusyError(RuntimeError):
    """The device is owned by another process (the message names its PID and command).

    Attributes
    ----------
    device : str
    holder : dict
        What the owner wrote into the lock file (``pid``, ``command``, ``since``), possibly
        empty.
    """

    def __init__(self, device: str, holder: dict, path: Path) -> None:
        pid = holder.get("pid", "unknown")
        command = holder.get("command", "")
        since = holder.get("since", "")
        detail = f" ({command})" if command else ""
        when = f" since {since}" if since else ""
        super().__init__(
            f"device {device!r} is in use by process {pid}{detail}{when}; "
            f"stop that program first (lock file {path})"
        )
        self.device = device
        self.holder = holder


def default_lock_dir() -> Path:
    """Where lock files go unless told otherwise (see the module notes)."""
    env = os.environ.get(LOCK_DIR_ENV)
    if env:
        return Path(env)
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime and Path(runtime).is_dir():
        return Path(runtime) / "clearance-rig"
    return Path.home() / ".cache" / "clearance-rig" / "locks"


def _file_name(device: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", device).strip("._") or "device"
    return f"{safe}.lock"


def _read_holder(path: Path) -> dict:
    try:
        text = path.read_text(encoding="utf-8").strip()
        return json.loads(text) if text else {}
    except (OSError, ValueError):
        return {}


def lock_holder(device: str, lock_dir: str | os.PathLike[str] | None = None) -> dict | None:
    """Who owns ``device`` now (``{"pid": ..., "command": ..., "since": ...}``), or None if free."""
    path = Path(lock_dir or default_lock_dir()) / _file_name(device)
    if not path.exists():
        return None
    with open(path, "a+") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_holder(path)
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
    return None


class DeviceLock:
    """Exclusive ownership of a device for the life of the object (or a ``with`` block).

    Parameters
    ----------
    device : str
        Device name (e.g. ``"cDAQ1"``, ``"sim-cDAQ1"``).
    lock_dir : path, optional
        Directory of the lock files (see :func:`default_lock_dir`).

    Raises
    ------
    DeviceBusyError
        From :meth:`acquire` if another process holds the device.

    Examples
    --------
    >>> with DeviceLock("cDAQ1"):  # doctest: +SKIP
    ...     backend = open_backend("ni", device="cDAQ1")
    """

    def __init__(self, device: str, lock_dir: str | os.PathLike[str] | None = None) -> None:
        if not isinstance(device, str) or not device.strip():
            raise ValueError(f"DeviceLock.device: expected a device name, got {device!r}")
        self.device = device
        self.lock_dir = Path(lock_dir) if lock_dir is not None else default_lock_dir()
        self.path = self.lock_dir / _file_name(device)
        self._fh = None

    @property
    def held(self) -> bool:
        return self._fh is not None

    def acquire(self) -> DeviceLock:
        """Take the lock or raise :class:`DeviceBusyError` at once (never waits)."""
        if self._fh is not None:
            return self
        self.lock_dir.mkdir(parents=True, exist_ok=True)
        fh = open(self.path, "a+", encoding="utf-8")  # noqa: SIM115 - held until release
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            raise DeviceBusyError(self.device, _read_holder(self.path), self.path) from None
        except BaseException:
            fh.close()
            raise
        holder = {
            "pid": os.getpid(),
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])[:200],
            "since": time.strftime("%Y-%m-%d %H:%M:%S"),
            "device": self.device,
        }
        fh.seek(0)
        fh.truncate()
        fh.write(json.dumps(holder))
        fh.flush()
        self._fh = fh
        logger.info("device %r locked (%s)", self.device, self.path)
        return self

    def release(self) -> None:
        """Give the device up (idempotent)."""
        fh, self._fh = self._fh, None
        if fh is None:
            return
        try:
            fh.seek(0)
            fh.truncate()
            fh.flush()
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
            fh.close()
        logger.info("device %r released", self.device)

    def __enter__(self) -> DeviceLock:
        return self.acquire()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()

    def __del__(self) -> None:
        if self._fh is not None:
            try:
                self.release()
            except Exception:
                pass
