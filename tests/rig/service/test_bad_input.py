"""Bad input to the acquisition service gets a 4xx with a reason, never a 500 (real server)."""

from __future__ import annotations

import json

import pytest

from rig.config.plans import load_plan
from tests.rig.service.test_service import _raw


def _auth(svc) -> dict:
    return {"Authorization": f"Bearer {svc.client().token}", "Content-Type": "application/json"}


@pytest.mark.timeout(60)
def test_a_non_utf8_authorization_header_is_refused_without_a_traceback(shared_service):
    svc = shared_service
    token = svc.client().token
    for value in (b"Bearer \xff\xfe" + token.encode(), b"Bearer " + token.encode() + b"\xe9"):
        status, _, data = _raw(svc, "GET", "/api/v1/runs", {"Authorization": value})
        assert status == 400, data
        error = json.loads(data)["error"]
        assert error["code"] == "bad-token" and "not ASCII" in error["message"]
    assert "Traceback" not in svc.output() and "Error handling request" not in svc.output()
    assert svc.proc.poll() is None


@pytest.mark.timeout(60)
def test_deeply_nested_json_is_refused(shared_service):
    svc = shared_service
    body = b"[" * 100_000 + b"]" * 100_000
    status, _, data = _raw(svc, "POST", "/api/v1/runs", _auth(svc), body)
    assert status == 400, data
    error = json.loads(data)["error"]
    assert error["code"] == "bad-json" and "nested" in error["message"]
    body = json.dumps({"plan": "quick", "label": "x"})[:-1].encode() + b', "n": ' + b"{" * 5000
    status, _, data = _raw(svc, "POST", "/api/v1/runs", _auth(svc), body)
    assert status == 400 and json.loads(data)["error"]["code"] == "bad-json", data
    assert "RecursionError" not in svc.output()


@pytest.mark.timeout(60)
def test_an_out_name_with_a_newline_or_other_control_character_is_refused(shared_service):
    svc = shared_service
    before = svc.client().runs()
    for out in ("ok\n", "ok\n.h5", "ok\r", "o\tk", "ok\x00"):
        body = json.dumps({"plan": "quick", "out": out}).encode()
        status, _, data = _raw(svc, "POST", "/api/v1/runs", _auth(svc), body)
        assert status == 400, (out, data)
        assert json.loads(data)["error"]["code"] == "bad-out"
    assert svc.client().runs() == before


@pytest.mark.timeout(60)
def test_a_plan_beyond_the_step_limit_is_refused_before_it_is_expanded(shared_service):
    from rig.config.plans import MAX_PLAN_STEPS

    svc = shared_service
    before = svc.client().runs()
    plan = load_plan("quick").to_dict()
    plan["frequencies"]["ranges"] = [{"start_hz": 21.0, "stop_hz": 40.0, "step_hz": 1e-9}]
    body = json.dumps({"plan": plan}).encode()
    status, _, data = _raw(svc, "POST", "/api/v1/runs", _auth(svc), body)
    assert status == 400, data
    error = json.loads(data)["error"]
    assert error["code"] == "plan-too-large"
    assert f"{MAX_PLAN_STEPS:,}" in error["message"] and "19,000,000,001" in error["message"]
    assert "step_hz" in error["message"]
    assert svc.client().runs() == before
    assert svc.proc.poll() is None


def test_a_token_that_is_not_ascii_does_not_match_and_does_not_raise():
    from rig.service.auth import token_matches

    token = "a" * 43
    assert token_matches(token, token)
    assert not token_matches("a" * 42 + "\udcff", token)  # an undecodable byte
    assert not token_matches("a" * 42 + "é", token)
