"""Finger gaiting through the manipulation planner's doors (docs/gait.md): a request with
``gait`` is planned by :func:`ocp.gait.planner.plan_gait` from the request's grasp, and
answered with the gait's phases, the joint trajectory over the whole plan and the
certificate of every phase and switch."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from dexroll_client.models import (
    GaitClockModel,
    GaitContactModel,
    GaitFingerModel,
    GaitHoldModel,
    GaitPhaseModel,
    GaitResultModel,
    GaitRollModel,
    GaitSamplesModel,
    GaitSwingModel,
    GaitTipModel,
    GaitTrajectoryModel,
    ManipulationCertificateModel,
    ManipulationRequest,
    ManipulationResult,
    ManipulationStatsModel,
    PlanStatus,
)
from ocp.gait.feasibility import MAX_ROLLS, gait_outlook
from ocp.gait.planner import GaitPlan, is_ball, plan_gait
from ocp.gait.samples import (
    LINK_CHECK_RATE,
    GaitSamples,
    gait_samples,
    gait_times,
    with_link_clearance,
)
from ocp.geometry.bodies import tip_body
from ocp.shapes.held import gait_shape_error
from ocp.solution import JointTrajectory, trajectory_joint_names
from ocp.spec.grasp import ManipulationProblem

from .common import finger_certificate, rows
from .fields import FieldErrors
from .samples import joint_trajectory_model
from .trajectory import manipulation_trajectory

__all__ = ["DEFAULT_GAIT_RATE", "gait_errors", "gait_result", "solve_gait"]

#: The joint trajectory's rate [Hz] of a gait without the request's ``sample_rate``.
DEFAULT_GAIT_RATE = 100.0


def gait_errors(request: ManipulationRequest, problem: ManipulationProblem) -> FieldErrors:
    """Why a request's ``gait`` cannot be planned, as (wire field, reason)."""
    if request.gait is None:
        return []
    errs: FieldErrors = []
    m = request.motion
    steps = getattr(m, "steps", None)
    if m is None or steps is None or len(steps) != 1:
        errs.append(("motion", "a gait turns the ball by one rotation step: give `motion` as "
                               "`steps` with one step (its axis and angle)"))
    elif any(abs(x) > 0.0 for x in steps[0].translation) or steps[0].angle <= 0.0:
        errs.append(("motion.steps", "a gait's step turns the ball about its centre: a "
                                     "positive angle, no translation"))
    if request.forces is None:
        errs.append(("forces", "a gait needs the ball's load: the other fingertips hold it "
                               "while one is lifted"))
    why = gait_shape_error(problem.object)
    if why is not None:
        errs.append(("object.shape", why))
    elif not is_ball(problem):
        for field, on in (("gait.landing", request.gait.landing != "home"),
                          ("gait.overlap", bool(request.gait.overlap))):
            if on:
                errs.append((field, f"planned on a ball alone (its landings found on the "
                                    f"ball, a turned ball filling the same space), not "
                                    f"yet on a {problem.object.shape}"))
    if request.palm is not None:
        errs.append(("palm", "a gait is planned for a ball held by fingertips alone"))
    if request.sample_times:  # (accepted and ignored before 2026-12-07)
        errs.append(("sample_times", "a gait's duration is its planner's (its rolls and "
                                     "re-placements), not the request's: give "
                                     "`sample_rate` (the gait is returned at that rate "
                                     "over its whole duration and at every phase switch)"))
    if len(problem.fingers) < 3:
        errs.append(("fingers", "a gait lifts one fingertip while the others hold the ball: "
                                f"at least three fingertips, got {len(problem.fingers)}"))
    for i, tip in enumerate(problem.fingers):
        kind = tip.finger.tip_surface.kind
        if kind not in ("sphere", "capsule"):
            errs.append((f"fingers[{i}]", f"a gait needs sphere or capsule fingertips "
                                          f"(their clearance), not a {kind}"))
    if problem.timing != "smooth":
        errs.append(("timing", "a gait's rolls start and end at rest: the smooth timing"))
    if request.gait is not None and steps is not None and len(steps) == 1 and \
            steps[0].angle > 0.0:
        need = math.ceil(float(steps[0].angle) / float(request.gait.roll_step) - 1e-9)
        if need > MAX_ROLLS:
            errs.append(("gait.roll_step",
                         f"{math.degrees(steps[0].angle):.1f} deg in rolls of at most "
                         f"{math.degrees(request.gait.roll_step):.2f} deg take {need} rolls; "
                         f"a gait plans at most {MAX_ROLLS}: a roll_step of at least "
                         f"{steps[0].angle / MAX_ROLLS:.4g} rad"))
    return errs


def solve_gait(request: ManipulationRequest, problem: ManipulationProblem, planner: Any
               ) -> tuple[ManipulationResult, GaitPlan]:
    """Plan the request's gait from the problem's grasp (its fingertips' joints)."""
    g = request.gait
    m = request.motion
    assert g is not None and m is not None and hasattr(m, "steps")
    step = m.steps[0]
    qs = tuple(np.asarray(tip.q_seed, dtype=float) for tip in problem.fingers)
    t0 = time.perf_counter()
    outlook = gait_outlook(problem, qs, step.axis, float(step.angle), float(g.roll_step))
    if not outlook.feasible:  # answered before any roll is planned
        gait = GaitPlan("infeasible", outlook.message, never_lifted=outlook.never_lifted,
                        nq=tuple(int(tip.finger.nq) for tip in problem.fingers),
                        wall_time=time.perf_counter() - t0)
        return gait_result(gait, problem, DEFAULT_GAIT_RATE), gait
    gait = plan_gait(problem, qs, step.axis, float(step.angle), roll_step=float(g.roll_step),
                     seconds_per_radian=float(step.duration) / float(step.angle),
                     planner=planner,
                     swing={"duration": float(g.swing_duration),
                            "clearance": float(g.clearance),
                            "fastest": bool(g.fastest_swings)},
                     hold_time=float(g.hold_time), replace_all=g.replace == "all",
                     fastest_rolls=bool(g.fastest_rolls), landing=str(g.landing),
                     overlap=bool(g.overlap))
    rate = float(getattr(request, "sample_rate", None) or DEFAULT_GAIT_RATE)
    # the result's samples serve the links' check when they are at least as dense
    smp = gait_samples(gait, problem, gait_times(gait, rate)) if gait.phases else None
    gait = with_link_clearance(gait, problem, smp if rate >= LINK_CHECK_RATE else None)
    return gait_result(gait, problem, rate, smp), gait


def _tip(finger: Any) -> GaitTipModel:
    """A finger's tip body on the wire (:func:`ocp.geometry.bodies.tip_body`)."""
    body = tip_body(finger)
    return GaitTipModel(kind=finger.tip_surface.kind, radius=float(body.r),
                        a=[float(v) for v in body.a], b=[float(v) for v in body.b])


def _touching(names: list[str], smp: GaitSamples) -> list[list[str]]:
    """At each sample, the fingertips touching the ball (:attr:`GaitSamples.touching`)."""
    assert smp.touching is not None
    return [[n for n, on in zip(names, row, strict=True) if on] for row in smp.touching]


def _message(gait: GaitPlan) -> str:
    """The gait's own message, or what its status and certificate say: never empty."""
    if gait.message:
        return gait.message
    if gait.status == "solved":
        failures = gait.certificate.failures
        return ("planned; certificate passed" if not failures else
                "planned, but the certificate failed: " + "; ".join(failures[:5]) +
                (f" (and {len(failures) - 5} more)" if len(failures) > 5 else ""))
    return f"the gait ended {gait.status} after {len(gait.rolls)} roll(s)"


def _status(gait: GaitPlan) -> PlanStatus:
    if gait.status == "solved":
        return PlanStatus.SOLVED if gait.certificate.passed else PlanStatus.INACCURATE
    if gait.status == "infeasible":
        return PlanStatus.INFEASIBLE
    last = gait.rolls[-1] if gait.rolls and gait.phases and \
        gait.phases[-1].kind == "roll" else None
    if last is not None and not last.ok:
        return PlanStatus(last.status.value)
    return PlanStatus.INFEASIBLE


def _pieces(gait: GaitPlan, names: list[str]) -> GaitTrajectoryModel | None:
    """The gait's pieces as they were certified (the wire's ``gait.trajectory``): every
    roll's plan at its collocation points with its clock, every swing's polynomials,
    every hold's joints and force ramp. None when a roll's plan is not finite."""
    rolls, swings, holds = [], [], []
    carried = {i: r for r, i in gait.carried.items()}  # step -> the roll it is made in
    for j, ph in enumerate(gait.phases):
        if ph.kind == "roll":
            r = ph.index
            traj = manipulation_trajectory(gait.rolls[r], gait.frames[r])
            if traj is None:
                return None
            c = gait.clock(r)
            rolls.append(GaitRollModel(
                phase=j, start=ph.start,
                clock=GaitClockModel(duration=c.duration, ramp=c.ramp, speed=c.speed),
                fingers=[names[i] for i in gait.fingers_of(r)], trajectory=traj))
            continue
        step = gait.steps[ph.index]
        holds.append(GaitHoldModel(
            phase=j, q=gait.still_joints(ph).tolist(),
            forces_start=rows(step.ramp_forces(ph.kind, 0.0)),
            forces_end=rows(step.ramp_forces(ph.kind, 1.0)),
            profile=step.ramp_profile))
    for i, step in enumerate(gait.steps):
        sw = step.swing
        if sw is None:
            continue
        kind, index = ("roll", carried[i]) if i in carried else ("swing", i)
        at = next((n for n, p in enumerate(gait.phases) if p.kind == kind and p.index == index),
                  None)
        if at is None:  # a swing not made: a failed gait's last step is kept with the swing
            continue    # it did not find, and has no phase
        swings.append(GaitSwingModel(phase=at, finger=names[step.finger],
                                     start=gait.phases[at].start, t=rows(sw.t), q=rows(sw.Q),
                                     q_dot=rows(sw.V), q_ddot=rows(sw.A), jerk=rows(sw.J)))
    return GaitTrajectoryModel(rolls=rolls, swings=swings, holds=holds)


def gait_result(gait: GaitPlan, problem: ManipulationProblem, rate: float,
                made: GaitSamples | None = None) -> ManipulationResult:
    """The wire result of a gait: its phases, the joints at ``rate`` [Hz] over the whole
    plan (ROS 2's JointTrajectory; ``made``: those samples, made already), the
    certificate."""
    names = [tip.name or f"finger{i}" for i, tip in enumerate(problem.fingers)]
    joint_names = trajectory_joint_names(
        [(nm, tip.finger.joint_names) for nm, tip in zip(names, problem.fingers, strict=True)])
    cut = np.cumsum([0, *(len(tip.finger.joint_names) for tip in problem.fingers)])
    jt, samples = None, None
    if gait.phases:
        smp = made if made is not None else gait_samples(gait, problem,
                                                        gait_times(gait, rate))
        jt = joint_trajectory_model(JointTrajectory(tuple(joint_names), smp.t, smp.q,
                                                    smp.q_dot, smp.q_ddot, (),
                                                    smp.effort),
                                    _touching(names, smp))
        assert smp.touching is not None and smp.object_velocity is not None
        assert smp.object_angular_velocity is not None
        assert smp.point_velocity is not None and smp.over_object is not None
        samples = GaitSamplesModel(
            t=smp.t.tolist(), object_position=rows(smp.object_position),
            object_orientation_wxyz=rows(smp.object_wxyz),
            object_velocity=rows(smp.object_velocity),
            object_angular_velocity=rows(smp.object_angular_velocity),
            contacts=[GaitContactModel(name=nm, active=smp.active[:, k].tolist(),
                                       touching=smp.touching[:, k].tolist(),
                                       point=rows(smp.point[:, k]),
                                       normal=rows(smp.normal[:, k]),
                                       force=rows(smp.force[:, k]),
                                       point_velocity=rows(smp.point_velocity[:, k]),
                                       velocity_over_object=rows(smp.over_object[:, k]))
                      for k, nm in enumerate(names)],
            fingers=[GaitFingerModel(name=nm, tip_position=rows(smp.tip_position[:, k]),
                                     tip_orientation_wxyz=rows(smp.tip_wxyz[:, k]),
                                     tip=_tip(tip.finger),
                                     joint_names=list(joint_names[cut[k]:cut[k + 1]]))
                     for k, (nm, tip) in enumerate(zip(names, problem.fingers,
                                                       strict=True))])
    block = GaitResultModel(
        phases=[GaitPhaseModel(kind=p.kind, start=p.start, end=p.end,
                               touching=list(p.touching),
                               lifted_finger=None if p.lifted is None else names[p.lifted])
                for p in gait.phases],
        turned=gait.turned, rolls=len(gait.rolls), replacements=gait.replacements,
        never_lifted=list(gait.never_lifted), wall_time=gait.wall_time, samples=samples,
        trajectory=_pieces(gait, names) if gait.phases else None)
    iterations = sum(r.iterations for r in gait.rolls) + \
        sum(s.swing.iterations for s in gait.steps if s.swing is not None)
    build = sum(r.build_time for r in gait.rolls)
    solve = sum(r.ipopt_time for r in gait.rolls) + \
        sum(s.swing.solve_time for s in gait.steps if s.swing is not None)
    cert = finger_certificate(ManipulationCertificateModel, gait.certificate) \
        if gait.certificate.checks else None
    return ManipulationResult(
        status=_status(gait), message=_message(gait),
        stats=ManipulationStatsModel(raw_status=gait.rolls[-1].raw_status if gait.rolls
                                     else "", iterations=iterations,
                                     build_time=build, solve_time=solve, refinements=0,
                                     n_intervals=problem.n_intervals),
        certificate=cert, joint_trajectory=jt, gait=block)
