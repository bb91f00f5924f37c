"""The plan viewer's scene and page (planner_service/view), the `dexroll view` command and
the service's view route, without a browser (tests/test_view_browser.py draws them)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from functools import cache
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from dexroll_client.models import AnyPlanResult, PlanRequest
from planner_service.cli import plan_request
from planner_service.planners import REQUEST
from planner_service.plans.models import infer_models, models_from_request
from planner_service.view import scene_of, tracks_of, view_html
from planner_service.view.page import page_html

ROOT = Path(__file__).resolve().parents[1]
#: One plan of each planner (the cheapest examples).
EXAMPLES = {"ball_on_palm": "triangle", "one_finger": "one_finger_roll",
            "manipulation": "experiment2_two_fingers"}


@pytest.fixture(scope="module")
def plans() -> dict[str, tuple[PlanRequest, AnyPlanResult, dict[str, Any]]]:
    out = {}
    for planner, name in EXAMPLES.items():
        raw = json.loads((ROOT / "examples" / f"{name}.json").read_text())
        result, summary = plan_request(raw)
        assert result.status.value == "solved", summary
        out[planner] = (REQUEST.validate_python(raw), result, raw)
    return out


def _poses(pose: dict[str, list[float]]) -> tuple[np.ndarray, np.ndarray]:
    return np.reshape(pose["p"], (-1, 3)), np.reshape(pose["q"], (-1, 4))


@pytest.mark.parametrize("planner", list(EXAMPLES))
def test_the_scene_has_every_pose_at_every_sample(plans: dict[str, Any], planner: str
                                                  ) -> None:
    request, result, raw = plans[planner]
    scene = scene_of(result, request)
    n = len(scene["t"])
    assert n > 10 and scene["planner"] == planner
    json.dumps(scene, allow_nan=False)  # plain JSON, finite
    p, q = _poses(scene["object"]["pose"])
    assert p.shape == (n, 3) and q.shape == (n, 4)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) > 0), "quaternions keep one sign"
    radius = raw.get("object", {}).get("dimensions", [0.025])[0]
    assert scene["object"]["shape"]["semi_axes"] == [radius] * 3
    for c in scene["contacts"]:
        assert len(c["point"]) == len(c["normal"]) == len(c["trace"]) == 3 * n
        # the trace on the object lies on its surface
        assert np.allclose(np.linalg.norm(np.reshape(c["trace"], (-1, 3)), axis=1), radius,
                           atol=1e-5)
    fingers = {"ball_on_palm": 0, "one_finger": 1, "manipulation": 2}[planner]
    assert len(scene["fingertips"]) == fingers
    for tip in scene["fingertips"]:
        assert tip["shape"]["kind"] == "pad" and tip["shape"]["half_size"] > 0
        tp, _ = _poses(tip["pose"])
        assert tp.shape == (n, 3)
        # the contact's trace on the pad lies in the pad's surface (z = 0)
        assert np.allclose(np.reshape(tip["trace"], (-1, 3))[:, 2], 0.0, atol=1e-5)
    moving = [b for b in scene["bodies"] if not b["static"]]
    assert len(moving) >= 6 * fingers
    assert (scene["palm"] is not None) == (planner != "manipulation" or
                                           raw.get("palm") is not None)
    if planner != "manipulation":
        assert scene["palm"]["half_extent"] > 0
    assert scene["phases"] is None  # a rolling plan: no contact schedule on the timeline


@cache
def allegro_plan() -> tuple[AnyPlanResult, dict[str, Any]]:
    """The built-in Allegro-class hand's example (capsule fingertips) planned, and its
    scene drawn with its request (about 5 s)."""
    raw = json.loads((ROOT / "examples" / "allegro_turn.json").read_text())
    result, summary = plan_request(raw)
    assert result.status.value == "solved", summary
    return result, scene_of(result, REQUEST.validate_python(raw))


def test_round_fingertips_are_drawn_as_the_models_tips() -> None:
    """The Allegro-class hand's capsule tips are capsules of the model's radius and length,
    at the URDF's collision capsule (19 mm along the tip link's z), the contact's trace on
    the cap (the pads of the other examples: test_the_scene_has_every_pose_at_every_sample)."""
    from ocp.robots.allegro import TIP_RADIUS
    from planner_service.plans.models import quaternion_matrices

    result, scene = allegro_plan()
    n = len(scene["t"])
    tips = scene["fingertips"]
    assert [t["name"] for t in tips] == ["index", "middle", "ring", "thumb"]
    for tip in tips:
        shape = tip["shape"]
        assert shape["kind"] == "capsule" and shape["radius"] == TIP_RADIUS
        half = shape["length"] / 2
        assert half in (0.01, 0.008)
        p, q = _poses(tip["pose"])
        assert p.shape == (n, 3) and q.shape == (n, 4)
        trace = np.reshape(tip["trace"], (-1, 3))
        # on the capsule's outer cap: radius from the cap's centre, beyond the cylinder
        cap = trace - [0.0, 0.0, half]
        assert np.allclose(np.linalg.norm(cap, axis=1), TIP_RADIUS, atol=1e-5)
        assert np.all(cap[:, 2] > 0.0)
    # the capsule's frame: the tip link's frame moved 19 mm along its z, z the link's z (the
    # URDF's collision capsule)
    for tip, finger in zip(tips, tracks_of(result).fingers, strict=True):
        R_link = quaternion_matrices(finger.tip_wxyz)
        p, q = _poses(tip["pose"])
        R = quaternion_matrices(q[:, [3, 0, 1, 2]])
        centre = 0.019 if tip["name"] != "thumb" else 0.043 - 0.008
        assert np.allclose(p, finger.tip_position + centre * R_link[:, :, 2], atol=1e-5)
        assert np.allclose(R[:, :, 2], R_link[:, :, 2], atol=1e-4)


def test_sphere_and_spheroid_tips_are_placed_by_their_pose() -> None:
    from ocp.geometry.tips import sphere_tip, spheroid_tip
    from planner_service.view.scene import _round_tip

    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    shape, R_s, p_s = _round_tip(sphere_tip(0.01, (0.0, 0.0, 0.02), R))
    assert shape == {"kind": "sphere", "radius": 0.01}
    assert np.allclose(R_s, R) and np.allclose(p_s, [0.0, 0.0, 0.02])
    shape, _, p_s = _round_tip(spheroid_tip(0.01, 0.015, (0.0, 0.005, 0.0)))
    assert shape == {"kind": "ellipsoid", "semi_axes": [0.01, 0.01, 0.015]}
    assert np.allclose(p_s, [0.0, 0.005, 0.0])


def test_links_move_rigidly_with_the_pad_by_the_models_kinematics(plans: dict[str, Any]
                                                                   ) -> None:
    """The last link (the fingertip stem) keeps its place relative to the pad, and the
    finger's FK at the plan's joints puts the pad where the plan has it."""
    request, result, _ = plans["one_finger"]
    scene = scene_of(result, request)
    tip_p, _ = _poses(scene["fingertips"][0]["pose"])
    stem = next(b for b in scene["bodies"] if b["name"] == "finger/link6_0")
    stem_p, _ = _poses(stem["pose"])
    d = np.linalg.norm(stem_p - tip_p, axis=1)
    assert np.ptp(d) < 1e-5 and d[0] > 0.005
    tracks = tracks_of(result)
    model = models_from_request(request, tracks).fingers[0]
    assert model is not None
    for k in (0, tracks.n // 2, tracks.n - 1):
        _, p = model.fingertip_pose_pin(tracks.fingers[0].q[k])
        assert np.allclose(p, tracks.fingers[0].tip_position[k], atol=1e-8)


@pytest.mark.parametrize("planner", ["one_finger", "manipulation"])
def test_without_the_request_the_models_are_inferred(plans: dict[str, Any], planner: str
                                                     ) -> None:
    request, result, _ = plans[planner]
    tracks = tracks_of(result)
    given, inferred = models_from_request(request, tracks), infer_models(tracks)
    assert inferred.shape == "sphere"
    assert math.isclose(inferred.dimensions[0], given.dimensions[0], rel_tol=1e-6)
    assert len(inferred.fingers) == len(given.fingers)
    for a, b in zip(inferred.fingers, given.fingers, strict=True):
        assert a is not None and b is not None
        assert a.joint_names == b.joint_names
        assert np.allclose(a.base_position, b.base_position)
        assert a.pad_half_size == b.pad_half_size
    bodies = {b["name"] for b in scene_of(result)["bodies"]}
    assert bodies == {b["name"] for b in scene_of(result, request)["bodies"]}


def test_the_page_is_self_contained(plans: dict[str, Any]) -> None:
    request, result, _ = plans["one_finger"]
    page = view_html(result, request, "a </script> title")
    assert page.startswith("<!DOCTYPE html>")
    lower = page.lower()
    assert "<script src" not in lower and "@import" not in lower
    assert lower.count("<link") == lower.count('<link rel="icon" href="data:')  # inlined
    assert lower.count("</script>") == 3  # the scene, three.js, the viewer: nothing escapes
    assert "a &lt;/script&gt; title" in page
    start = page.index('type="application/json">') + len('type="application/json">')
    scene = json.loads(page[start:page.index("</script>", start)])
    assert scene == json.loads(json.dumps(scene_of(result, request, "a </script> title")))
    assert page_html(scene) == page


def dexroll(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "planner_service.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300, check=False)


def test_dexroll_view_writes_the_page(plans: dict[str, Any], tmp_path: Path) -> None:
    request, result, raw = plans["one_finger"]
    (tmp_path / "plan.result.json").write_text(result.model_dump_json())
    (tmp_path / "request.json").write_text(json.dumps(raw))
    proc = dexroll("view", "plan.result.json", "--request", "request.json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / "plan.result.html").read_text()
    assert page == view_html(result, request, "plan.result.json")
    # a job's JSON (GET /v1/plans/{id}) is read too, its id the title
    job = {"id": "abc", "state": "succeeded", "planner": "one_finger",
           "created_at": "2026-01-01T00:00:00Z", "result": result.model_dump(mode="json")}
    (tmp_path / "job.json").write_text(json.dumps(job))
    (tmp_path / "out").mkdir()
    proc = dexroll("view", "job.json", "-o", "out/job.html", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "<title>job abc - dexroll</title>" in (tmp_path / "out/job.html").read_text()
    # no plan, not a result: exit 2 with the reason
    (tmp_path / "bad.json").write_text('{"status": "invalid_input", "message": "no"}')
    proc = dexroll("view", "bad.json", cwd=tmp_path)
    assert proc.returncode == 2 and "no plan" in proc.stderr
    (tmp_path / "junk.json").write_text("[1, 2")
    proc = dexroll("view", "junk.json", cwd=tmp_path)
    assert proc.returncode == 2 and "cannot read" in proc.stderr


def test_the_service_links_and_serves_the_view(live_server: Any) -> None:
    raw = json.loads((ROOT / "examples" / "triangle.json").read_text())
    with httpx.Client(base_url=live_server.url, timeout=120) as http:
        job = http.post("/v1/plans", params={"wait": 100}, json=raw).json()
        assert job["state"] == "succeeded", job
        assert job["links"]["view"] == f"/v1/plans/{job['id']}/view"
        assert http.get(f"/v1/plans/{job['id']}").json()["links"] == job["links"]
        r = http.get(job["links"]["view"])
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        assert f"<title>job {job['id']} - dexroll</title>" in r.text
        assert http.get(job["links"]["view"]).text == r.text  # cached, the same page
        missing = http.get("/v1/plans/no-such-job/view")
        assert missing.status_code == 404 and missing.json()["error"] == "not_found"


def test_a_gaits_scene_carries_its_contact_schedule() -> None:
    """The stored gait (tests/data/gait_small_*.json; drawn in the browser by
    tests/test_view_browser.py): the scene's phases are the result's, tiling the plan's
    time, and each contact's activity is given at every sample."""
    from planner_service.planners import RESULT

    data = ROOT / "tests" / "data"
    result = RESULT.validate_json((data / "gait_small_result.json").read_text())
    request = REQUEST.validate_json((data / "gait_small_request.json").read_text())
    scene = scene_of(result, request)
    assert result.gait is not None
    assert [(p["kind"], p["lifted"]) for p in scene["phases"]] == \
        [(p.kind, p.lifted_finger) for p in result.gait.phases]
    starts = [p["start"] for p in scene["phases"]]
    ends = [p["end"] for p in scene["phases"]]
    assert starts[0] == scene["t"][0] and ends[-1] == pytest.approx(scene["t"][-1], abs=1e-6)
    assert starts[1:] == pytest.approx(ends[:-1], abs=1e-6)
    n = len(scene["t"])
    assert all(len(c["active"]) == n for c in scene["contacts"])
    assert 'id="schedule"' in view_html(result, request)
