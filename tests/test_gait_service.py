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
from helpers import assert_gait_pieces

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
        # the ball's velocity: the rate of its samples' positions and orientations (central
        # differences within a roll, 10 ms apart: within 5 % of the roll's peak, the
        # difference's own error in the clock's ramps), at rest while a fingertip is
        # re-placed; the touching flags: every fingertip but the one a swing carries
        v = np.array(gait.samples.object_velocity)
        w = np.array(gait.samples.object_angular_velocity)
        pos = np.array(gait.samples.object_position)
        Rs = [_matrix(q) for q in gait.samples.object_orientation_wxyz]
        for p in gait.phases:
            inside = np.flatnonzero((t > p.start + 0.02) & (t < p.end - 0.02))
            if p.kind != "roll":
                assert np.all(v[inside] == 0.0) and np.all(w[inside] == 0.0)
                continue
            v_peak = np.linalg.norm(v[inside], axis=1).max()
            w_peak = np.linalg.norm(w[inside], axis=1).max()
            assert w_peak > 0.0
            for i in inside[1:-1]:
                dt = t[i + 1] - t[i - 1]
                fd = (pos[i + 1] - pos[i - 1]) / dt
                assert np.linalg.norm(fd - v[i]) <= 0.05 * v_peak + 2e-7  # (a held centre)
                dR = Rs[i + 1] @ Rs[i - 1].T  # the spatial angular velocity's rotation
                wfd = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0],
                                dR[1, 0] - dR[0, 1]]) / (2 * dt)
                assert np.linalg.norm(wfd - w[i]) <= 0.05 * w_peak
        # the contacts' velocities: the rate of their samples' points (as the ball's
        # above), and their motion over the ball tangent to it where the tip touches, zero
        # where the ball is still and the tip on it, and equal to their motion over the
        # tip's own body (no slip: the two bodies' material points at the contact move
        # together)
        for f, c in zip(gait.samples.fingers, gait.samples.contacts, strict=True):
            assert c.point_velocity is not None and c.velocity_over_object is not None
            pv, over = np.array(c.point_velocity), np.array(c.velocity_over_object)
            pts, nrm = np.array(c.point), np.array(c.normal)
            on = np.array(c.touching, dtype=bool)
            tp = np.array(f.tip_position)
            TR = [_matrix(q_) for q_ in f.tip_orientation_wxyz]
            for p in gait.phases:
                inside = np.flatnonzero((t > p.start + 0.02) & (t < p.end - 0.02))
                peak = np.linalg.norm(pv[inside], axis=1).max()
                for i in inside[1:-1]:
                    dt = t[i + 1] - t[i - 1]
                    fd = (pts[i + 1] - pts[i - 1]) / dt
                    assert np.linalg.norm(fd - pv[i]) <= 0.05 * peak + 1e-7, (p.kind, i)
                    if not on[i]:
                        continue
                    assert abs(over[i] @ nrm[i]) <= 1e-6 * max(peak, 1.0)
                    if p.kind != "roll":
                        assert np.linalg.norm(over[i]) <= 1e-9
                        continue
                    dR = TR[i + 1] @ TR[i - 1].T
                    w_tip = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0],
                                      dR[1, 0] - dR[0, 1]]) / (2 * dt)
                    v_tip = (tp[i + 1] - tp[i - 1]) / dt + np.cross(w_tip, pts[i] - tp[i])
                    assert np.linalg.norm(pv[i] - v_tip - over[i]) <= 0.05 * peak + 1e-7
        # the tips' bodies: where a fingertip touches, its cap's surface meets the ball's
        # (the distance from the ball's centre to its cap's centre is the two radii)
        rho = float(small()["object"]["dimensions"][0])
        for f, c in zip(gait.samples.fingers, gait.samples.contacts, strict=True):
            assert f.tip is not None and f.tip.kind in ("sphere", "capsule")
            a = np.array(f.tip.a)
            cap = [np.array(p_) + _matrix(q_) @ a
                   for p_, q_ in zip(f.tip_position, f.tip_orientation_wxyz, strict=True)]
            gap = np.linalg.norm(np.array(cap) - pos, axis=1) - rho - f.tip.radius
            on = np.array(c.touching, dtype=bool)
            assert on.any() and np.abs(gap[on]).max() < 1e-5, np.abs(gap[on]).max()
            if (~on).any():
                assert gap[~on].max() > 1e-4  # lifted clear somewhere in its swing
        touched = [p.touching for p in jt.points]
        for c in gait.samples.contacts:
            assert c.touching is not None
            assert c.touching == [c.name in names for names in touched]
        for p in gait.phases:
            if p.kind == "swing":
                c = next(c for c in gait.samples.contacts if c.name == p.lifted_finger)
                inside = (t >= p.start) & (t < p.end)
                assert c.touching is not None and not any(np.array(c.touching)[inside])
        # joints continuous, at rest at every switch: no jump between samples beyond what
        # the rates allow, zero rates where a phase ends
        q = np.array([p.positions for p in jt.points])
        qd = np.array([p.velocities for p in jt.points])
        assert np.all(np.abs(np.diff(q, axis=0)) <= np.abs(qd).max() * np.diff(t)[:, None]
                      + 1e-9)
        for p in gait.phases:
            at = int(np.argmin(np.abs(t - p.end)))
            assert abs(t[at] - p.end) < 1e-9 and np.abs(qd[at]).max() < 1e-6
        # ... and the accelerations continuous too: zero at every switch (a roll starts and
        # ends still on its clock, a swing at rest, a hold is still), and no step between
        # samples beyond what a bounded jerk allows
        qdd = np.array([p.accelerations for p in jt.points])
        for p in gait.phases:
            for edge in (p.start, p.end):
                at = int(np.argmin(np.abs(t - edge)))
                assert abs(t[at] - edge) < 1e-9 and np.abs(qdd[at]).max() < 1e-6, edge
        jerk = np.abs(np.diff(qdd, axis=0)).max(axis=1) / np.diff(t)
        assert jerk.max() < 2000.0  # rad/s^3: a jump of 1 rad/s^2 in one 10 ms sample fails
        # the pieces as certified: the samples are them at their times (any time, by the
        # client's GaitResultModel.joints_at)
        assert_gait_pieces(result)
        # the ball turned by the request about its axis, its centre held (tracking 1 mm,
        # 1 deg)
        R = _matrix(gait.samples.object_orientation_wxyz[-1])
        want = _axis_angle((0.0, -1.0, 0.0), math.radians(8.0))
        assert math.degrees(math.acos(min(1.0, (np.trace(want.T @ R) - 1) / 2))) <= 1.0
        pos = np.array(gait.samples.object_position)
        assert np.linalg.norm(pos - pos[0], axis=1).max() <= 1e-3
        report = client.simulate(job.id)
        # the viewer draws it: the contacts' activity is in the page's scene
        page = client.http.get(f"/v1/plans/{job.id}/view")
        assert page.status_code == 200 and '"active":[1.0' in page.text
    # executed in MuJoCo: no contact lost, no touch while a fingertip is carried clear,
    # and each re-placed fingertip off the ball (no normal force) while it is
    assert report.passed, report.failures
    assert all(c.lost_time == 0.0 and c.unplanned_touch_time == 0.0
               for c in report.contacts)
    assert report.series is not None
    ts = np.array(report.series.t)
    for p in gait.phases:
        if p.kind != "swing":
            continue
        c = next(c for c in gait.samples.contacts if c.name == p.lifted_finger)
        clear = t[(np.array(c.active) == 0.0)]
        clear = clear[(clear > p.start) & (clear < p.end)]
        mask = (ts >= clear.min() + 0.01) & (ts <= clear.max() - 0.01)
        force = np.array(report.series.normal_force[p.lifted_finger])
        assert mask.any() and np.all(force[mask] == 0.0)
    last = gait.phases[-1]
    during = (ts > last.start + 0.1) & (ts < last.end - 0.1)
    assert all(np.all(np.array(f)[during] > 0.0) for f in report.series.normal_force.values())


def _matrix(wxyz: list[float]) -> np.ndarray:
    w, x, y, z = wxyz
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _axis_angle(axis: tuple[float, float, float], angle: float) -> np.ndarray:
    k = np.asarray(axis) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_a_gait_whose_swing_is_not_found_is_a_typed_result_over_http(
        live_server: Server) -> None:
    """A clearance no swing can keep (50 mm from the ball): the first re-placement is not
    found, the rolls are halved twice, and the answer is a result naming the swing, with
    the roll that was made. (The failed step is kept with the swing it did not find and
    has no phase: the result's pieces raised StopIteration on it, and the job failed.)"""
    from dexroll_client import DexrollClient

    body = small()
    body["gait"]["clearance"] = 0.05
    with DexrollClient.from_url(live_server.url, timeout=120) as client:
        result = client.plan(body, timeout=600).result
    assert isinstance(result, ManipulationResult), result
    assert result.status is PlanStatus.INFEASIBLE, result.message
    assert "the swing of finger 'index' was not found" in result.message
    assert "clearance from the ball" in result.message
    gait = result.gait
    assert gait is not None and gait.rolls == 1 and gait.replacements == 0
    assert [p.kind for p in gait.phases] == ["roll"]
    assert gait.trajectory is not None and gait.trajectory.swings == []
    assert len(gait.trajectory.rolls) == 1
