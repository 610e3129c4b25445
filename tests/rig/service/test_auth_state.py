"""The token file, the service directory and the persisted run records (no processes)."""

from __future__ import annotations

import json
import os
import stat
import threading

import pytest

from rig.config.plans import load_plan
from rig.service.auth import bearer_token, ensure_token, read_token, token_matches
from rig.service.client import ServiceClient, ServiceUnavailable, _plan_payload
from rig.service.directory import ServiceDir, default_service_dir
from rig.service.state import ServiceState


def test_the_token_is_made_once_user_only_and_kept(tmp_path):
    path = tmp_path / "token"
    token, created = ensure_token(path)
    assert created and len(token) >= 40
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    again, created = ensure_token(path)
    assert again == token and not created
    assert read_token(path) == token


def test_a_token_file_others_can_read_is_replaced(tmp_path):
    path = tmp_path / "token"
    token, _ = ensure_token(path)
    os.chmod(path, 0o644)
    new, created = ensure_token(path)
    assert created and new != token
    assert stat.S_IMODE(path.stat().st_mode) == 0o600


def test_bearer_header_parsing_and_comparison():
    assert bearer_token("Bearer abc") == "abc"
    assert bearer_token("bearer  abc ") == "abc"
    assert bearer_token("Basic abc") is None
    assert bearer_token("Bearer") is None and bearer_token(None) is None
    assert token_matches("abc", "abc") and not token_matches("abd", "abc")
    assert not token_matches(None, "abc") and not token_matches("", "abc")


def test_service_directory_defaults_and_is_user_only(tmp_path, monkeypatch):
    monkeypatch.setenv("RIG_SERVICE_DIR", str(tmp_path / "env"))
    assert default_service_dir() == tmp_path / "env"
    monkeypatch.delenv("RIG_SERVICE_DIR")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    assert default_service_dir() == tmp_path / "state" / "clearance-rig" / "service"
    sdir = ServiceDir(tmp_path / "svc")
    sdir.create()
    assert stat.S_IMODE(sdir.root.stat().st_mode) == 0o700
    assert sdir.read_endpoint() is None
    sdir.write_endpoint({"host": "127.0.0.1", "port": 1, "pid": 5})
    assert stat.S_IMODE(sdir.endpoint_path.stat().st_mode) == 0o600
    sdir.remove_endpoint(6)  # someone else's: kept
    assert sdir.read_endpoint()["pid"] == 5
    sdir.remove_endpoint(5)
    assert not sdir.endpoint_path.exists()


def test_client_without_a_service_says_how_to_start_one(tmp_path, monkeypatch):
    monkeypatch.delenv("RIG_SERVICE_URL", raising=False)
    with pytest.raises(ServiceUnavailable, match="rig service start"):
        ServiceClient.connect(tmp_path)
    # an address where nothing listens
    client = ServiceClient("127.0.0.1", _free_port(), "t" * 43, timeout_s=2)
    with pytest.raises(ServiceUnavailable):
        client.status()


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_plans_are_sent_as_data(tmp_path):
    assert _plan_payload("quick") == "quick"
    plan = load_plan("quick")
    assert _plan_payload(plan) == plan.to_dict()
    path = tmp_path / "mine.toml"
    path.write_text('name = "mine"\n[excitation]\nlevels_n = [1.0]\n')
    assert _plan_payload(str(path)) == {"name": "mine", "excitation": {"levels_n": [1.0]}}
    path.write_text("name = ")
    with pytest.raises(ValueError, match="not valid TOML"):
        _plan_payload(path)


def test_run_records_survive_a_restart_and_active_runs_become_interrupted(tmp_path):
    path = tmp_path / "state.json"
    state = ServiceState.load(path)
    plan = load_plan("quick")
    a = state.add(plan, tmp_path / "a.h5")
    b = state.add(plan, tmp_path / "b.h5", label="second")
    c = state.add(plan, tmp_path / "c.h5")
    assert [a.id, b.id, c.id] == ["r0001", "r0002", "r0003"]
    taken = state.take_next(threading.Event())
    assert taken is a and a.state == "running" and a.attempts == 1
    state.cancel(c, "not needed")
    assert stat.S_IMODE(path.stat().st_mode) == 0o600

    again = ServiceState.load(path)  # as after a crash
    ra, rb, rc = (again.get(x) for x in ("r0001", "r0002", "r0003"))
    assert ra.state == "interrupted" and "under way" in ra.message and ra.resumable
    assert rb.state == "interrupted" and "before the run started" in rb.message
    assert rb.label == "second" and rb.plan == plan.to_dict()
    assert rc.state == "cancelled" and not rc.resumable
    assert again.queue == [] and again.new_id() == "r0004"
    again.requeue(ra)
    assert ra.state == "queued" and ra.resume and again.queue == ["r0001"]
    with pytest.raises(ValueError):
        again.requeue(rc)
    stored = json.loads(path.read_text())
    assert stored["next_number"] == 4 and len(stored["runs"]) == 3


def test_take_next_returns_none_once_stopping(tmp_path):
    state = ServiceState.load(tmp_path / "state.json")
    stopping = threading.Event()
    threading.Timer(0.2, stopping.set).start()
    assert state.take_next(stopping, poll_s=0.05) is None
