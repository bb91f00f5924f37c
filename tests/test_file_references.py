"""Issue 25, part 3: the service reads no path a request names. A URDF's ``<mesh
filename=...>`` pointing at a sentinel file is observed by the file's access time (the
kernel updates it when the file is read: the sentinel's is set older than its modification
time, which ``relatime`` mounts update on a read), first read by Pinocchio's own geometry
loader (so that the observation is real), then never read by the viewer's model loading,
in this process and through ``GET /v1/plans/{id}/view`` on a real service. The DOCTYPE
rule holds over the whole text; an MJCF naming a file is refused, naming the element."""

from __future__ import annotations

import contextlib
import json
import os
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pinocchio as pin
import pytest
from conftest import Server

from ocp import load_finger
from ocp.robots.finger import builtin_urdf_text
from planner_service.models_check import ModelLimits, tree_errors, without_file_references
from planner_service.plans.shapes import pad_thickness
from planner_service.view.robot import finger_bodies

ROOT = Path(__file__).resolve().parents[1]


def sentinel(folder: Path) -> Path:
    """A mesh file whose access time moves when something reads it."""
    path = folder / "sentinel.stl"
    path.write_text("solid s\nendsolid s\n")
    reset(path)
    return path


def reset(path: Path) -> None:
    now = time.time()
    os.utime(path, (now - 3600.0, now))


def was_read(path: Path) -> bool:
    st = path.stat()
    return st.st_atime > st.st_mtime - 1.0


def urdf_with_mesh(path: Path) -> str:
    """The built-in finger's URDF with a mesh visual on its first moving link."""
    mesh = (f'<visual><geometry><mesh filename="{path}"/></geometry>'
            f'<material name="m"><texture filename="{path}"/></material></visual>')
    return builtin_urdf_text().replace('<link name="link1">', f'<link name="link1">{mesh}', 1)


def test_the_viewers_model_loading_opens_no_file_the_urdf_names(tmp_path: Path) -> None:
    path = sentinel(tmp_path)
    text = urdf_with_mesh(path)
    finger = load_finger(text)
    # the observation is real: Pinocchio's geometry loader reads the mesh it is given
    with contextlib.suppress(Exception):  # the sentinel is no mesh; its read counts
        pin.buildGeomFromUrdfString(finger.model, text, pin.GeometryType.VISUAL)
    assert was_read(path)
    reset(path)
    assert not was_read(path)
    bodies = finger_bodies(finger, np.zeros((3, finger.nq)), "f_")
    assert bodies and pad_thickness(finger) > 0
    assert not was_read(path)
    stripped = without_file_references(text)
    assert str(path) not in stripped and "<mesh" not in stripped and "link1" in stripped


def test_the_doctype_rule_holds_over_the_whole_text() -> None:
    hidden = ("<!--" + "x" * 5000 + '-->\n<!DOCTYPE robot SYSTEM "file:///etc/passwd">'
              '<robot name="r"><link name="fingertip"/></robot>')
    (reason,) = tree_errors("urdf", hidden, ModelLimits())
    assert "DOCTYPE or entities" in reason
    lower = "<!--" + "y" * 9000 + '--><!doctype robot><robot name="r"/>'
    assert "DOCTYPE" in tree_errors("urdf", lower, ModelLimits())[0]


def test_an_mjcf_naming_a_file_is_refused_naming_the_element(tmp_path: Path) -> None:
    path = sentinel(tmp_path)
    mjcf = (f'<mujoco><include file="{path}"/><worldbody><body><joint/></body></worldbody>'
            '</mujoco>')
    (reason,) = tree_errors("mjcf", mjcf, ModelLimits())
    assert "<include> names a file" in reason and str(path) in reason
    assert not was_read(path)


def test_the_services_viewer_opens_no_file_a_request_names(live_server: Server,
                                                           tmp_path: Path) -> None:
    path = sentinel(tmp_path)
    request: dict[str, Any] = json.loads((ROOT / "examples" / "one_finger_roll.json")
                                         .read_text())
    request["n_intervals"] = 16
    with httpx.Client(base_url=live_server.url, timeout=300) as http:
        (k3s,) = [f for f in http.get("/v1/models").json()["fingers"] if f["name"] == "k3s"]
        request["finger"] = {"urdf": urdf_with_mesh(path), "tip_frame": k3s["tip_frame"],
                             "base_position": k3s["base_position"],
                             "base_rotation": k3s["base_rotation"], "pad_half_size": 0.05}
        r = http.post("/v1/plans", params={"wait": 30}, json=request)
        assert r.status_code in (201, 202), r.text
        job = r.json()
        deadline = time.monotonic() + 300
        while job["state"] in ("queued", "running") and time.monotonic() < deadline:
            time.sleep(0.5)
            job = http.get(f"/v1/plans/{job['id']}").json()
        assert job["state"] == "succeeded", job
        r = http.get(f"/v1/plans/{job['id']}/view")
        assert r.status_code == 200 and "<html" in r.text.lower()
    assert not was_read(path)


def test_the_viewer_loads_under_the_model_checkers_limits(server_factory: Any) -> None:
    """The service's page of a plan is built (its request's models loaded) in a process
    of its own under the model checker's limits: past the time limit (0.02 s here: the
    finger's model and geometry loaded, its links posed at every sample) a 409 naming the
    limit, the service answering; the page built in a process whose address space is
    capped."""
    from planner_service.models_check import ModelChecker, Task, TaskError

    server = server_factory(DEXROLL_MODEL_CHECK_SECONDS="0.02", DEXROLL_WORKERS="1")
    request = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    # 200 intervals: the page poses the links at every sample, 0.05-0.09 s here on a quiet
    # machine (at 16 intervals 0.014 s: under the limit, and this test failed once)
    request["n_intervals"] = 200
    with httpx.Client(base_url=server.url, timeout=300) as http:
        job = http.post("/v1/plans", params={"wait": 240}, json=request).json()
        assert job["state"] == "succeeded", job
        r = http.get(f"/v1/plans/{job['id']}/view")
        assert r.status_code == 409, r.text[:300]
        assert r.json()["error"] == "not_viewable"
        assert "longer than the 0.02 s allowed" in r.json()["message"]
        assert http.get("/healthz").status_code == 200
        stored = http.get(f"/v1/plans/{job['id']}").json()
    # the same page in a viewer process of this test's (under the default limits): built
    # there, with the process's address space capped as the model checker's are
    viewer = ModelChecker(ModelLimits(), lazy=True)
    try:
        page = viewer.call(Task("view", (json.dumps(stored["result"]), json.dumps(request),
                                         "job")))
        assert "<html" in page
        (proc,) = viewer._all
        limits = Path(f"/proc/{proc.process.pid}/limits").read_text()
        (line,) = [x for x in limits.splitlines() if x.startswith("Max address space")]
        assert line.split()[3] != "unlimited", line
        with pytest.raises(TaskError) as raised:  # the task's own refusal comes back
            viewer.call(Task("view", ('{"planner": "one_finger"}', json.dumps(request),
                                      "job")))
        assert raised.value.kind == "ValidationError"
    finally:
        viewer.close()
