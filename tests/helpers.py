"""Shared test helpers (import as ``from helpers import assert_close``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ocp import presets
from ocp.one_finger import FingerContact
from ocp.spec.grasp import ManipulationProblem
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ViaPoint


def _as_float_array(x: Any) -> np.ndarray:
    """A float array from numpy data, Python numbers or a CasADi DM (``np.array(DM)`` works)."""
    return np.array(x, dtype=float)


def assert_close(actual: Any, expected: Any, atol: Any, rtol: float = 0.0,
                 err_msg: str = "") -> None:
    """Assert |actual - expected| <= atol + rtol |expected| element by element.

    Unlike ``np.allclose`` it has no default tolerance (state it at the call), and it fails
    on any NaN or inf in ``actual`` or ``expected`` (NaN never passes as "close").
    ``expected`` may be a scalar (compared with every element of ``actual``); otherwise the
    shapes must agree, up to singleton axes (a CasADi column (n, 1) matches a numpy (n,)).
    ``atol`` is a number or an array of per-element tolerances of the compared shape.
    """
    atol_arr = np.asarray(atol, dtype=float)
    if not (np.all(np.isfinite(atol_arr)) and np.all(atol_arr >= 0.0) and np.isfinite(rtol)
            and rtol >= 0.0):
        raise ValueError(f"tolerances must be finite and >= 0, got atol={atol}, rtol={rtol}")
    a = _as_float_array(actual)
    e = _as_float_array(expected)
    prefix = f"{err_msg}: " if err_msg else ""
    if not np.all(np.isfinite(a)):
        raise AssertionError(f"{prefix}actual has non-finite entries:\n{a}")
    if not np.all(np.isfinite(e)):
        raise AssertionError(f"{prefix}expected has non-finite entries:\n{e}")
    if e.ndim > 0 and a.shape != e.shape:
        if np.squeeze(a).shape != np.squeeze(e).shape:
            raise AssertionError(f"{prefix}shape mismatch: actual {a.shape}, expected {e.shape}")
        a, e = np.squeeze(a), np.squeeze(e)
    err = np.abs(a - e)
    tol = np.broadcast_to(np.squeeze(atol_arr) if atol_arr.ndim else atol_arr,
                          err.shape) + rtol * np.abs(e)
    bad = err > tol
    if np.any(bad):
        worst = tuple(int(i) for i in np.unravel_index(np.argmax(err - tol), err.shape))
        raise AssertionError(
            f"{prefix}{int(np.sum(bad))} of {err.size} entries differ by more than "
            f"atol + rtol*|expected| (rtol={rtol:g}); worst at {worst}: "
            f"actual={a[worst]!r}, expected={np.broadcast_to(e, a.shape)[worst]!r}, "
            f"error={err[worst]:.3e}, tolerance={tol[worst]:.3e}\n"
            f"actual:\n{a}\nexpected:\n{e}"
        )


def experiment1(goal: dict[str, float], duration: float = 2.0, n_intervals: int = 16,
                via_points: tuple[ViaPoint, ...] = ()) -> ManipulationProblem:
    """The paper's experiment-1 grasp: the built-in finger pressing the 25 mm ball on the
    palm, rolled to the palm ``goal`` (through ``via_points``) in ``duration`` seconds,
    mu = 0.5."""
    base = BallOnPalmProblem(object=ObjectSpec("sphere", (0.025,)),
                             initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2), goal=goal,
                             duration=duration, n_intervals=n_intervals,
                             via_points=via_points)
    contact = FingerContact(initial=(0.0, 0.0, 0.2, 0.0, 0.0),
                            chart_rotation=(0.0, 0.0, math.pi),
                            q_seed=tuple(math.radians(a) for a in (0, 30, 0, 30, 0, 30)))
    return presets.one_finger(base, contact, mu=0.5)


def nominal_turn(mjcf: str, tips: list[str], angle: float = 0.1, duration: float = 1.0,
                 hand: dict[str, Any] | None = None, **extra: Any) -> dict[str, Any]:
    """A manipulation request body: the built-in hand's nominal grasp (its joints, the
    60 mm ball where they touch it) on the MJCF hand ``mjcf`` with fingertips ``tips``,
    turned by ``angle`` [rad] about the palm's z in ``duration`` [s]; ``hand``: more of the
    hand's fields, ``extra``: more of the request's."""
    from ocp.robots.allegro import NOMINAL_OBJECT_POSITION, NOMINAL_Q, NOMINAL_RADIUS

    return {
        "planner": "manipulation", "object": {"shape": "sphere",
                                              "dimensions": [NOMINAL_RADIUS]},
        "hand": {"mjcf": mjcf, "tips": [{"name": t} for t in tips], **(hand or {})},
        "fingers": [{"hand_finger": k, "initial_q": list(q)}
                    for k, q in enumerate(NOMINAL_Q)],
        "initial_pose": {"position": list(NOMINAL_OBJECT_POSITION),
                         "orientation_wxyz": [1, 0, 0, 0]},
        "motion": {"kind": "steps", "steps": [{"duration": duration, "axis": [0, 0, 1],
                                               "angle": angle}]},
        "duration": duration, **extra}


def wrist_wrapped(own: str) -> str:
    """A hand in examples/own_hand.xml's layout (``own``) carried by a forearm's two wrist
    joints (their axes through the world origin, position servos of their own), as a
    Shadow-style arm carries its hand; the index's spread joint limited by a fixed tendon
    over it alone."""
    start, end = own.index("<worldbody>") + len("<worldbody>"), own.index("</worldbody>")
    wrapped = (own[:start] + """
    <body name="wrist_a">
      <joint name="WRJ1" axis="0 1 0" range="-28 8" damping="1"/>
      <inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
      <body name="wrist_b">
        <joint name="WRJ0" axis="1 0 0" range="-40 28" damping="1"/>
        <inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>""" +
               own[start:end] + """
      </body>
    </body>
  """ + own[end:])
    limit = """
    <fixed name="T_ffj0" limited="true" range="-0.004 0.004">
      <joint joint="ffj0" coef="0.01"/>
    </fixed>"""
    if "<tendon>" in wrapped:
        wrapped = wrapped.replace("<tendon>", "<tendon>" + limit, 1)
    else:
        wrapped = wrapped.replace("<actuator>", f"<tendon>{limit}\n  </tendon>\n  <actuator>",
                                  1)
    return wrapped.replace("<actuator>", """<actuator>
    <position name="A_WRJ1" joint="WRJ1" kp="10" ctrlrange="-28 8"/>
    <position name="A_WRJ0" joint="WRJ0" kp="10" ctrlrange="-40 28"/>""", 1)


def planned_and_executed(raw: dict[str, Any], position: float = 2e-3, degrees: float = 3.0,
                         model: str | None = None) -> tuple[Any, Any]:
    """Plan the request ``raw`` (a dict as a client sends it) through the service's own
    door and execute it in MuJoCo (in dexroll's scene; ``model`` "request": on the
    request's own MJCF hand, driven by its own actuators), asserting the laws of a good
    plan: solved, its certificate passed, executed within ``position`` [m] and ``degrees``
    with no planned contact lost. (result, execution report)."""
    from dexroll_client.models import PlanStatus
    from planner_service.cli import plan_request
    from planner_service.execution import simulate_result
    from planner_service.planners import REQUEST

    result, summary = plan_request(raw)
    assert result.status is PlanStatus.SOLVED, summary
    assert result.certificate is not None and result.certificate.passed, summary
    report = simulate_result(result, REQUEST.validate_python(raw), model=model)
    assert report.passed, report.failures
    assert report.position_error.max <= position
    assert math.degrees(report.angle_error.max) <= degrees
    assert all(c.lost_time == 0.0 for c in report.contacts)
    return result, report


def planned_gait(raw: dict[str, Any]) -> tuple[Any, Any, Any, Any]:
    """Plan the gait request ``raw`` through the service's adapter on a fresh finger
    cache, asserting that it is certified: (request, problem, result, gait plan)."""
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.gait import solve_gait
    from planner_service.planners.manipulation import manipulation_problem

    request = REQUEST.validate_python(raw)
    cache = FingerCache()
    problem = manipulation_problem(request, cache)
    result, gait = solve_gait(request, problem, cache.manipulation)
    assert gait.ok and result.certificate is not None and result.certificate.passed, \
        result.message
    return request, problem, result, gait


def assert_gait_pieces(result: Any) -> None:
    """The law of a gait result's ``gait.trajectory`` (its pieces as certified): the joint
    trajectory's every sample is those pieces at its time (:meth:`GaitResultModel.
    joints_at`, to rounding: the samples are made from the same polynomials), the samples'
    forces inside each hold are its ramp's, and each roll's last collocation point has the
    ball where the samples have it at the roll's end (its orientation in the palm
    frame)."""
    gait, jt = result.gait, result.joint_trajectory
    assert gait is not None and gait.trajectory is not None and gait.samples is not None
    assert jt is not None
    pieces = gait.trajectory
    kinds = [p.kind for p in gait.phases]
    assert sorted(r.phase for r in pieces.rolls) == \
        [i for i, k in enumerate(kinds) if k == "roll"]
    assert sorted(h.phase for h in pieces.holds) == \
        [i for i, k in enumerate(kinds) if k != "roll"]
    assert len(pieces.swings) == gait.replacements
    for p in jt.points:
        q, v, a = (np.array(x) for x in gait.joints_at(p.t))
        assert_close(q, np.array(p.positions), 1e-10, err_msg=f"q at {p.t}")
        assert_close(v, np.array(p.velocities), 1e-8, err_msg=f"q_dot at {p.t}")
        assert_close(a, np.array(p.accelerations), 1e-6, err_msg=f"q_ddot at {p.t}")
    t = np.array(gait.samples.t)
    for h in pieces.holds:
        ph = gait.phases[h.phase]
        for i in np.flatnonzero((t > ph.start + 1e-9) & (t < ph.end - 1e-9)):
            x = (t[i] - ph.start) / (ph.end - ph.start)
            s = x if h.profile == "linear" else x * x * (3.0 - 2.0 * x)
            want = (1 - s) * np.array(h.forces_start) + s * np.array(h.forces_end)
            got = np.array([c.force[i] for c in gait.samples.contacts])
            assert_close(got, want, 1e-9, err_msg=f"hold forces at {t[i]}")
    for r in pieces.rolls:
        end = int(np.argmin(np.abs(t - gait.phases[r.phase].end)))
        w0 = np.array(r.trajectory.object_orientation_wxyz[-1])
        w1 = np.array(gait.samples.object_orientation_wxyz[end])
        assert min(np.abs(w0 - w1).max(), np.abs(w0 + w1).max()) < 1e-6
