"""The device lock: one owner per device, across threads and processes, released by the OS."""

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from rig.lock import DeviceBusyError, DeviceLock, default_lock_dir, lock_holder
from rig.runner import open_rig
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
        from rig.lock import DeviceLock
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
