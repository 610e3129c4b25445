"""One process at a time owns a device: an OS-level lock file per device name.

The command line, the GUI and the acquisition service all take :class:`DeviceLock` before they
open a DAQ device, so two programs never drive the same shaker. The lock is ``fcntl.flock`` on
``<lock_dir>/<device>.lock``: the operating system releases it when the owner exits, however it
exits (a crash or ``kill -9`` leaves no stale lock). The file holds the owner's PID, command
line and start time, which a second would-be owner sees in its error message.

Lock directory, first that applies: the ``lock_dir`` argument (``--lock-dir``), the
``RIG_LOCK_DIR`` environment variable, else one directory that every process on the machine sees,
whoever runs it and whatever its environment: ``/run/lock/clearance-rig`` (``/var/lock``, then
``/tmp`` where there is no ``/run/lock``). A per-user directory would let two users, or two
environments of one user, drive the same shaker at once. The directory is made world-writable
with the sticky bit (like ``/tmp``: anyone may create a lock file, nobody may delete another's),
and lock files are readable and writable by all, so that any user can take a free device and see
who holds a busy one. Lock files are opened without ``O_CREAT`` when they exist, which
``fs.protected_regular`` would refuse for another user's file in a sticky directory.

Simulated devices exist once per process, not once per machine: :func:`rig.run.session.open_rig`
locks them in :func:`user_lock_dir` (``RIG_LOCK_DIR``, ``$XDG_RUNTIME_DIR/clearance-rig`` or
``~/.cache/clearance-rig/locks``) so that two users can each run the simulator.
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

__all__ = ["DeviceBusyError", "DeviceLock", "default_lock_dir", "lock_holder", "user_lock_dir"]

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


SYSTEM_LOCK_DIRS = ("/run/lock", "/var/lock", "/tmp")
"""Machine-wide parents of the lock directory, first existing writable one wins."""

LOCK_DIR_NAME = "clearance-rig"


def default_lock_dir() -> Path:
    """Where lock files go unless told otherwise: ``RIG_LOCK_DIR``, else the machine-wide
    directory (see the module notes), the same for every user and environment."""
    env = os.environ.get(LOCK_DIR_ENV)
    if env:
        return Path(env)
    for parent in SYSTEM_LOCK_DIRS:
        if os.path.isdir(parent) and os.access(parent, os.W_OK | os.X_OK):
            return Path(parent) / LOCK_DIR_NAME
    return Path("/tmp") / LOCK_DIR_NAME


def user_lock_dir() -> Path:
    """A per-user lock directory (for simulated devices): ``RIG_LOCK_DIR``,
    ``$XDG_RUNTIME_DIR/clearance-rig`` or ``~/.cache/clearance-rig/locks``."""
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


def _make_shared_dir(path: Path) -> None:
    """Create the lock directory; a machine-wide one world-writable with the sticky bit."""
    if path.is_dir():
        return
    path.mkdir(parents=True, exist_ok=True)
    if str(path.parent) in SYSTEM_LOCK_DIRS:
        try:
            os.chmod(path, 0o1777)
        except OSError as exc:  # made by someone else in the meantime
            logger.debug("cannot chmod %s: %s", path, exc)


def _open_lock_file(path: Path):
    """Open (creating if need be) a lock file, readable and writable by every user."""
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            fd = os.open(path, os.O_RDWR)
        else:
            try:
                os.fchmod(fd, 0o666)  # whatever the umask: other users must open it too
            except OSError:
                pass
    except PermissionError:
        fd = os.open(path, os.O_RDONLY)  # enough to lock and to read the holder
    return os.fdopen(fd, "r+" if os.access(path, os.W_OK) else "r", encoding="utf-8")


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
    with _open_lock_file(path) as fh:
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
        _make_shared_dir(self.lock_dir)
        fh = _open_lock_file(self.path)
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
        if fh.writable():
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
            if fh.writable():
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
