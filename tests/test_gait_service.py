"""Finger gaiting through the service's doors (docs/gait.md): a request with `gait` is
planned over HTTP into phases, a joint trajectory over the whole plan and a certificate,
executed in MuJoCo through the simulation route; requests a gait cannot serve are a 422
naming the field, before any NLP is built."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from dexroll_client import ManipulationResult, PlanStatus
from tests.conftest import Server

EXAMPLE = json.loads((Path(__file__).resolve().parents[1] / "examples" /
                      "allegro_gait.json").read_text())


def small() -> dict[str, Any]:
    """The example turned 8 deg in two rolls of 4 deg (the suite's time)."""
    body = copy.deepcopy(EXAMPLE)
    body["motion"]["steps"][0].update(angle=math.radians(8.0), duration=1.2)
    body["duration"] = 1.2
    body["gait"]["roll_step"] = math.radians(4.0)
    body["n_intervals"] = 10
    return body


def _fields(server: Server, body: dict[str, Any]) -> dict[str, str]:
    r = httpx.post(f"{server.url}/v1/plans", params={"wait": 0}, content=json.dumps(body),
                   headers={"content-type": "application/json"}, timeout=60)
    assert r.status_code == 422, r.text
    out: dict[str, str] = {}
    for d in r.json()["detail"]:
        out[d["field"]] = out.get(d["field"], "") + d["reason"] + "; "
    return out


def test_a_gait_a_request_cannot_have_is_422_naming_the_field(live_server: Server) -> None:
    body = small()
    del body["forces"]
    assert "hold it" in _fields(live_server, body)["forces"]
    body = small()
    body["motion"]["steps"] = [dict(body["motion"]["steps"][0], duration=0.6)] * 2
    assert "one rotation step" in _fields(live_server, body)["motion"]
    body = small()
    body["fingers"] = body["fingers"][:2]
    assert "at least three" in _fields(live_server, body)["fingers"]
    body = small()
    body["gait"]["roll_step"] = 0.0
    assert "gait.roll_step" in _fields(live_server, body)


def test_a_gait_is_planned_and_executed_over_http(live_server: Server) -> None:
    from dexroll_client import DexrollClient

    with DexrollClient.from_url(live_server.url, timeout=120) as client:
        job = client.plan(small(), timeout=600)
        result = job.result
        assert isinstance(result, ManipulationResult), result
        assert result.status is PlanStatus.SOLVED, result.message
        assert result.certificate is not None and result.certificate.passed
        gait = result.gait
        assert gait is not None and gait.samples is not None
        kinds = [p.kind for p in gait.phases]
        assert kinds == ["roll"] + ["unload", "swing", "load"] * 3 + ["roll"]
        assert [p.lifted_finger for p in gait.phases if p.kind == "swing"] == \
            ["index", "middle", "ring"] and gait.never_lifted == ["thumb"]
        assert math.degrees(gait.turned) == np.float64(8.0).round(9)
        # a lifted fingertip: inactive and without force while clear of the ball
        jt = result.joint_trajectory
        assert jt is not None and len(jt.joint_names) == 16
        t = np.array([p.t for p in jt.points])
        assert np.allclose(t, gait.samples.t) and t[-1] == gait.phases[-1].end
        for p in gait.phases:
            c = next(c for c in gait.samples.contacts if c.name == (p.lifted_finger or ""))\
                if p.kind == "swing" else None
            if c is not None:
                inside = (t > p.start) & (t < p.end)
                act = np.array(c.active)[inside]
                assert act.min() == 0.0
                assert np.all(np.linalg.norm(np.array(c.force)[inside], axis=1) == 0.0)
        # joints continuous: no jump between samples beyond what the rates allow
        q = np.array([p.positions for p in jt.points])
        qd = np.array([p.velocities for p in jt.points])
        assert np.all(np.abs(np.diff(q, axis=0)) <= np.abs(qd).max() * np.diff(t)[:, None]
                      + 1e-9)
        report = client.simulate(job.id)
        # the viewer draws it: the contacts' activity is in the page's scene
        page = client.http.get(f"/v1/plans/{job.id}/view")
        assert page.status_code == 200 and '"active":[1.0' in page.text
    assert report.passed, report.failures
