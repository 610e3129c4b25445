"""The device lock: one owner per device, across threads and processes, released by the OS."""

import os
import signal
import stat
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

from rig.run.lock import (
    SYSTEM_LOCK_DIRS,
    DeviceBusyError,
    DeviceLock,
    default_lock_dir,
    lock_holder,
)
from rig.run.session import open_rig
from tests.rig.rig_helpers import setup_at


def test_second_owner_gets_an_error_naming_the_holder(tmp_path):
    first = DeviceLock("cDAQ1", tmp_path).acquire()
    assert lock_holder("cDAQ1", tmp_path)["pid"] == os.getpid()
    with pytest.raises(DeviceBusyError) as err:
        DeviceLock("cDAQ1", tmp_path).acquire()
    assert f"process {os.getpid()}" in str(err.value) and "'cDAQ1'" in str(err.value)
    assert err.value.holder["pid"] == os.getpid()
    DeviceLock("Dev2", tmp_path).acquire().release()  # another device is free
    first.release()
    assert lock_holder("cDAQ1", tmp_path) is None
    with DeviceLock("cDAQ1", tmp_path) as again:
        assert again.held
    assert not again.held


def test_lock_held_by_another_process_and_freed_when_it_is_killed(tmp_path):
    code = textwrap.dedent(
        f"""
        import time
        from rig.run.lock import DeviceLock
        lock = DeviceLock("cDAQ1", {str(tmp_path)!r}).acquire()
        print("locked", flush=True)
        time.sleep(60)
        """
    )
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "locked"
        with pytest.raises(DeviceBusyError, match=f"in use by process {child.pid}"):
            DeviceLock("cDAQ1", tmp_path).acquire()
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(10)
    with DeviceLock("cDAQ1", tmp_path):  # the OS released it with the process
        pass


def test_open_rig_takes_the_lock(tmp_path):
    setup = setup_at()
    with open_rig("sim", setup, lock_dir=tmp_path) as rig:
        assert rig.lock_name == "sim-cDAQ1"
        with pytest.raises(DeviceBusyError):
            with open_rig("sim", setup, lock_dir=tmp_path):
                pass
    with open_rig("sim", setup, lock_dir=tmp_path):
        pass


def test_lock_directory_from_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("RIG_LOCK_DIR", str(tmp_path / "locks"))
    assert default_lock_dir() == tmp_path / "locks"
    with DeviceLock("a/b:c") as lock:
        assert lock.path.parent == tmp_path / "locks" and "/" not in lock.path.name
    monkeypatch.delenv("RIG_LOCK_DIR")
    assert "clearance-rig" in str(default_lock_dir())


def _env_of_another_user(tmp_path, who):
    """An environment as another user's would be: own HOME, XDG dirs and TMPDIR, no
    RIG_LOCK_DIR."""
    home = tmp_path / who
    (home / "run").mkdir(parents=True)
    env = {k: v for k, v in os.environ.items() if k != "RIG_LOCK_DIR"}
    env.update(
        HOME=str(home),
        XDG_RUNTIME_DIR=str(home / "run"),
        XDG_CACHE_HOME=str(home / "cache"),
        TMPDIR=str(home),
        USER=who,
    )
    return env


def test_two_users_see_each_others_lock_of_a_real_device(tmp_path):
    device = f"cDAQ-test-{uuid.uuid4().hex[:8]}"
    holder_code = textwrap.dedent(
        f"""
        import time
        from rig.run.lock import DeviceLock
        lock = DeviceLock({device!r}).acquire()
        print(lock.path, flush=True)
        time.sleep(60)
        """
    )
    taker_code = textwrap.dedent(
        f"""
        from rig.run.lock import DeviceBusyError, DeviceLock
        try:
            DeviceLock({device!r}).acquire()
        except DeviceBusyError as exc:
            print("busy:", exc)
        else:
            print("taken")
        """
    )
    first = subprocess.Popen(
        [sys.executable, "-c", holder_code],
        stdout=subprocess.PIPE,
        text=True,
        env=_env_of_another_user(tmp_path, "alice"),
    )
    path = None
    try:
        path = Path(first.stdout.readline().strip())
        assert str(tmp_path) not in str(path)  # not under anyone's home
        second = subprocess.run(
            [sys.executable, "-c", taker_code],
            capture_output=True,
            text=True,
            env=_env_of_another_user(tmp_path, "bob"),
            timeout=60,
        )
        assert second.stdout.startswith("busy:"), second.stdout + second.stderr
        assert f"process {first.pid}" in second.stdout
        assert stat.S_IMODE(path.parent.stat().st_mode) == 0o1777  # world-writable, sticky
        assert stat.S_IMODE(path.stat().st_mode) == 0o666
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        if path is not None and path.name.startswith("cDAQ-test-"):
            path.unlink(missing_ok=True)


def test_the_lock_dir_option_still_overrides(tmp_path, monkeypatch):
    monkeypatch.delenv("RIG_LOCK_DIR", raising=False)
    assert default_lock_dir().parent in {Path(p) for p in SYSTEM_LOCK_DIRS}
    with DeviceLock("cDAQ1", tmp_path / "mine") as lock:
        assert lock.path.parent == tmp_path / "mine"
