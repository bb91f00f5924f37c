"""The plan viewer in a real browser: Debian's headless Chromium (`make test` installs
it) driven by Playwright, one browser for the module.

A real service (uvicorn on loopback) plans the one-finger example; its view is drawn from
the service, then the same page saved as a file is drawn with the service stopped and the
browser offline, and `dexroll view` of the job's JSON writes the same page."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import start_server

from planner_service.view.browser import CHROMIUM, launch, open_view

ROOT = Path(__file__).resolve().parents[1]

if not Path(CHROMIUM).exists():
    pytest.skip(f"no {CHROMIUM}: `make test` installs Debian's chromium (as root)",
                allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api")
Image = pytest.importorskip("PIL.Image")


@dataclass
class Visit:
    """What a page did in the browser: console errors, uncaught exceptions, the URLs it
    asked for, and screenshots of its canvas at given plan times."""

    errors: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    shots: dict[str, np.ndarray] = field(default_factory=dict)
    duration: float = 0.0
    failure: str | None = None
    #: the directive that refused a script added to the page afterwards (None: it ran)
    refused_by: str | None = None
    #: the window's and the 3D view's heights [px], whether the schedule is shown
    layout: dict[str, Any] = field(default_factory=dict)


#: Adds an inline script the page's policy does not name; what refused it (or null).
INJECT = """() => new Promise(done => {
  document.addEventListener("securitypolicyviolation",
                            e => done(e.effectiveDirective), {once: true});
  const s = document.createElement("script");
  s.textContent = "window.injected = true";
  document.body.appendChild(s);
  setTimeout(() => done(window.injected ? null : "not run, no report"), 2000);
})"""


#: The window's height, the 3D view's and the timeline bar's, and the schedule's display.
LAYOUT = """() => ({window: innerHeight,
  view: document.querySelector("#view canvas").getBoundingClientRect().height,
  bar: document.getElementById("bar").getBoundingClientRect().height,
  schedule: getComputedStyle(document.getElementById("schedule")).display,
  scheduleHeight: document.getElementById("schedule").getBoundingClientRect().height})"""


def visit(context: Any, url: str, times: dict[str, float]) -> Visit:
    v = Visit()
    page = context.new_page()
    page.on("console", lambda m: v.errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: v.errors.append(f"uncaught: {e}"))
    page.on("request", lambda r: v.requests.append(r.url))
    open_view(page, url)
    v.failure = page.evaluate("window.dexroll.error")
    v.duration = float(page.evaluate("window.dexroll.duration"))
    v.layout = page.evaluate(LAYOUT)
    canvas = page.locator("#view canvas")
    for name, frac in times.items():
        page.evaluate("t => window.dexroll.setTime(t)", frac * v.duration)
        png = canvas.screenshot()
        v.shots[name] = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
    errors = list(v.errors)  # the page's own (a policy violation is a console error)
    v.refused_by = page.evaluate(INJECT)
    page.close()
    v.errors = errors
    return v


TIMES = {"start": 0.0, "middle": 0.5, "start again": 0.0}


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with sync_api.sync_playwright() as p:
        context = launch(p, tmp_path_factory.mktemp("chromium-profile"))
        yield context
        context.close()


@pytest.fixture(scope="module")
def served(browser: Any, tmp_path_factory: pytest.TempPathFactory
           ) -> Iterator[tuple[Visit, Path, str]]:
    """The view as the service serves it, visited while the service runs; then the page
    and the job saved to files and the service stopped."""
    folder = tmp_path_factory.mktemp("view")
    server = start_server(folder / "data", DEXROLL_WORKERS="1")
    try:
        raw = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
        with httpx.Client(base_url=server.url, timeout=300) as http:
            job = http.post("/v1/plans", params={"wait": 240}, json=raw).json()
            assert job["state"] == "succeeded", job
            page = http.get(job["links"]["view"])
            assert page.status_code == 200
            policy = page.headers["content-security-policy"]
        seen = visit(browser, server.url + job["links"]["view"], TIMES)
    finally:
        server.stop()
    (folder / "plan.html").write_text(page.text, encoding="utf-8")
    (folder / "job.json").write_text(json.dumps(job), encoding="utf-8")
    (folder / "request.json").write_text(json.dumps(raw), encoding="utf-8")
    yield seen, folder, policy


def differs(a: np.ndarray, b: np.ndarray) -> float:
    """The fraction of pixels that differ between two screenshots."""
    assert a.shape == b.shape
    return float(np.mean(np.any(np.abs(a - b) > 8, axis=2)))


def test_the_served_view_draws_without_errors(served: tuple[Visit, Path, str]) -> None:
    """With the service's Content-Security-Policy on: no violation (a console error), the
    page drawn, and a script it does not name refused."""
    seen, _, policy = served
    assert policy.startswith("default-src 'none'; script-src 'sha256-")
    assert "unsafe" not in policy and "frame-ancestors 'none'" in policy
    assert seen.failure is None and seen.errors == []
    assert seen.refused_by == "script-src-elem"
    assert seen.duration == pytest.approx(2.0)
    # the page is the only request: three.js and the plan are inlined
    assert len(seen.requests) == 1 and seen.requests[0].endswith("/view")


def test_the_canvas_is_not_blank(served: tuple[Visit, Path, str]) -> None:
    shot = served[0].shots["start"]
    background = np.array([0xF4, 0xF5, 0xF7], dtype=float)
    drawn = np.mean(np.any(np.abs(shot - background) > 8, axis=2))
    assert drawn > 0.05, f"only {drawn:.1%} of the canvas differs from the background"
    assert len(np.unique(shot.reshape(-1, 3), axis=0)) > 200  # shading, not a flat fill


def test_a_rolling_plans_view_fills_the_window(served: tuple[Visit, Path, str]) -> None:
    """A plan without contact phases shows no schedule, and its 3D view takes the whole
    window but the timeline bar (the hidden schedule's canvas was shown at its default
    size: the view was 225 px tall in a 900 px window)."""
    layout = served[0].layout
    assert layout["schedule"] == "none"
    assert layout["view"] >= layout["window"] - layout["bar"] - 2, layout


def test_the_object_moves_along_the_timeline(served: tuple[Visit, Path, str]) -> None:
    shots = served[0].shots
    assert differs(shots["start"], shots["middle"]) > 0.002
    assert differs(shots["start"], shots["start again"]) < 0.001  # drawn the same each time


def test_the_standalone_file_draws_the_same_offline(browser: Any,
                                                    served: tuple[Visit, Path, str]
                                                    ) -> None:
    seen, folder, _ = served  # the service is stopped
    browser.set_offline(True)
    try:
        alone = visit(browser, (folder / "plan.html").as_uri(), TIMES)
    finally:
        browser.set_offline(False)
    assert alone.failure is None and alone.errors == []
    assert alone.refused_by == "script-src-elem"  # the page's own <meta> policy
    assert alone.requests == [(folder / "plan.html").as_uri()]
    for name in TIMES:
        assert differs(alone.shots[name], seen.shots[name]) < 0.001, name


def test_dexroll_view_writes_the_served_page(served: tuple[Visit, Path, str]) -> None:
    _, folder, _ = served
    proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "view", "job.json",
                           "--request", "request.json", "-o", "cli.html"], cwd=folder,
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    assert (folder / "cli.html").read_text() == (folder / "plan.html").read_text()


def test_round_fingertips_draw_without_errors(browser: Any, tmp_path: Path) -> None:
    """The Allegro-class hand's plan: capsule fingertips (sphere and capsule meshes)."""
    from test_view import allegro_plan

    from planner_service.view.page import page_html

    _, scene = allegro_plan()
    assert {t["shape"]["kind"] for t in scene["fingertips"]} == {"capsule"}
    file = tmp_path / "allegro.html"
    file.write_text(page_html(scene), encoding="utf-8")
    seen = visit(browser, file.as_uri(), {"start": 0.0})
    assert seen.failure is None and seen.errors == []


@pytest.mark.parametrize(("shape", "dims"), [("capsule", (0.012, 0.028)),
                                             ("superellipsoid", (0.025, 0.02, 0.03, 0.005))])
def test_other_objects_draw_without_errors(browser: Any, tmp_path: Path, shape: str,
                                           dims: tuple[float, ...]) -> None:
    """The object drawn as its shape's record says: a capsule (three's capsule turned onto
    the object's z axis), a superellipsoid (a sphere's mesh pushed out to its surface),
    shaded, without errors."""
    from test_view import allegro_plan

    from ocp import shape_of
    from planner_service.view.page import page_html

    _, scene = allegro_plan()
    scene["object"]["shape"] = {**shape_of(shape).viewer(dims), "object": shape}
    file = tmp_path / f"{shape}.html"
    file.write_text(page_html(scene), encoding="utf-8")
    seen = visit(browser, file.as_uri(), {"start": 0.0})
    assert seen.failure is None and seen.errors == []
    shot = seen.shots["start"]
    background = np.array([0xF4, 0xF5, 0xF7], dtype=float)
    assert np.mean(np.any(np.abs(shot - background) > 8, axis=2)) > 0.02


#: A gait planned once (tests/data/gait_small_request.json: examples/allegro_gait.json
#: turned 8 deg in two rolls of 4 deg, index, middle and ring re-placed; 20 Hz samples) and
#: its result as the service returned it: still a valid result of today's schema.
GAIT_REQUEST = ROOT / "tests" / "data" / "gait_small_request.json"
GAIT_RESULT = ROOT / "tests" / "data" / "gait_small_result.json"


def test_a_gaits_contact_schedule_is_on_the_timeline(browser: Any, tmp_path: Path) -> None:
    """One row per fingertip under the timeline, in its contact's colour where it touches
    and blank while it is lifted clear (its activity in the result's samples), the
    phases named above it; the lifted finger named during its swing."""
    from planner_service.planners import REQUEST, RESULT
    from planner_service.view import view_html

    result = RESULT.validate_json(GAIT_RESULT.read_text())  # the stored result's schema
    request = REQUEST.validate_json(GAIT_REQUEST.read_text())
    gait = result.gait
    assert gait is not None and gait.samples is not None
    swings = [p for p in gait.phases if p.kind == "swing"]
    assert [p.lifted_finger for p in swings] == ["index", "middle", "ring"]
    file = tmp_path / "gait.html"
    file.write_text(view_html(result, request), encoding="utf-8")
    page = browser.new_page()
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"uncaught: {e}"))
    open_view(page, file.as_uri())
    layout = page.evaluate(LAYOUT)  # the view, the bar and the schedule fill the window
    assert layout["schedule"] == "block" and layout["scheduleHeight"] > 50
    assert layout["view"] >= layout["window"] - layout["bar"] - layout["scheduleHeight"] - 2
    scene = json.loads(page.locator("#dexroll-scene").text_content())
    colors = {c["name"]: np.array([int(c["color"][i:i + 2], 16) for i in (1, 3, 5)],
                                  dtype=float) for c in scene["contacts"]}
    # the lifted finger named while it is carried clear
    for p in swings:
        page.evaluate("t => window.dexroll.setTime(t)", (p.start + p.end) / 2)
        assert page.locator("#phase").text_content() == f"swing ({p.lifted_finger} lifted clear)"
        assert page.locator("#lifted").text_content() == f"lifted: {p.lifted_finger}"
    page.evaluate("t => window.dexroll.setTime(t)", 0.0)
    shot = np.asarray(Image.open(io.BytesIO(page.locator("#schedule").screenshot()))
                      .convert("RGB"), dtype=float)

    def pixel(name: str, t: float) -> np.ndarray:
        x, y = page.evaluate("([n, t]) => window.dexroll.schedulePoint(n, t)", [name, t])
        return shot[round(y), int(x)]

    for p in gait.phases:
        mid = (p.start + p.end) / 2
        for name, color in colors.items():
            got = pixel(name, mid)
            if p.kind == "swing" and name == p.lifted_finger:
                assert np.abs(got - 255.0).max() <= 8, (p.kind, name, got)  # blank
            elif p.kind in ("roll", "swing"):
                assert np.abs(got - color).max() <= 8, (p.kind, name, got, color)
    assert errors == []
    page.close()
