"""A plan's contact forces in two stages (docs/forces.md): the kinematic plan first, then
the forces at its collocation points (:class:`~ocp.transcription.force_stage.ForceStage`),
certified with them; and the statistics of a plan that followed another."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from ocp.solution import ManipulationSolution, Status
from ocp.solve.assemble import assemble_solution, planned_forces
from ocp.solve.certify import with_force_checks
from ocp.solve.guesses import planned_force_guess
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.spec.patches import planned_problem
from ocp.transcription.chart_switch import PlanCharts
from ocp.transcription.force_stage import ForceStage
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.values import load_parameters

__all__ = ["with_earlier", "with_forces"]


def with_forces(model: Callable[[ManipulationProblem], GraspModel],
                stages: dict[GraspModel, ForceStage], problem: ManipulationProblem,
                kin: ManipulationSolution) -> ManipulationSolution | None:
    """The kinematic plan ``kin`` of ``problem`` with its forces (the force stage at its
    collocation points), certified; None when some point admits no forces or the
    certificate fails with them. ``model``: the planner's grasp models, ``stages``: its
    force stages by model (built here when missing)."""
    col = kin.collocation
    if col is None or kin.stats is None:
        return None
    # on the plan's own charts (its palm patch, an egg's side chart)
    pf = planned_problem(problem.with_intervals(len(col.t_nodes) - 1),
                         kin.object_chart_rotation, kin.object_side_chart)
    if pf is None:
        return None
    m = model(pf)
    prm = m.params(np.asarray(pf.object.params, dtype=float), contact_charts(pf))
    # the kinematic plan's charts (two when its contacts change chart at a node)
    charts = kin._interpolant.charts if kin._interpolant is not None \
        and kin._interpolant.charts.switched else PlanCharts.single(m, prm)
    Xall = np.vstack([col.X, col.Xm])
    pc = charts.point_charts(len(col.Xm))
    load = load_parameters(pf)
    model_rows = _model_torques(pf, kin, col, m.fingertips)
    F = None
    iterations, t_build, t_stage = 0, 0.0, 0.0
    for c in sorted(set(pc.tolist())):  # the points of each chart: one stage each
        idx = np.flatnonzero(pc == c)
        mc, prm_c = charts.models[c], charts.prms[c]
        t0 = time.perf_counter()
        if mc not in stages:
            stages[mc] = ForceStage(mc)
        stage = stages[mc]
        stage.prepare(len(idx))
        t_build += time.perf_counter() - t0
        t0 = time.perf_counter()
        Fc, it = _stage_forces(stage, pf, Xall[idx], prm_c, load,
                               None if model_rows is None else [r[idx] for r in model_rows])
        iterations += it
        t_stage += time.perf_counter() - t0
        if Fc is None:
            return None
        if F is None:
            F = np.zeros((Fc.shape[0], len(Xall)))
        F[:, idx] = Fc
    assert F is not None
    forces = planned_forces(pf, m, F, col.X, col.Xm, prm, charts)
    t_cert = time.perf_counter()
    cert = with_force_checks(kin.certificate, pf, m, kin.trajectory, prm, pf.tolerances,
                             forces, charts)
    if not cert.passed:
        return None
    sol = assemble_solution(pf, m, Status.SOLVED, kin.raw_status, replace(col, forces=forces),
                            kin.trajectory, prm, cert, kin.goal_error, charts)
    t_cert = time.perf_counter() - t_cert
    stats = replace(kin.stats, iterations=kin.stats.iterations + iterations,
                    build_time=kin.stats.build_time + t_build,
                    solve_time=kin.stats.solve_time + t_stage,
                    ipopt_time=kin.stats.ipopt_time + t_stage,
                    certificate_time=kin.stats.certificate_time + t_cert)
    return replace(sol, stats=stats, nlp_point=kin.nlp_point,
                   object_chart_rotation=kin.object_chart_rotation,
                   object_side_chart=kin.object_side_chart)


#: The share of each actuator's torque range a roll's forces may ask of its joint (the rest
#: for the motion's own terms: damping, inertia).
ROLL_TORQUE_SHARE = 0.9


def _stage_forces(stage: ForceStage, problem: ManipulationProblem, Xall: np.ndarray,
                  prm: np.ndarray, load: np.ndarray, model_rows: list[np.ndarray] | None
                  ) -> tuple[np.ndarray | None, int]:
    """The force stage at the points ``Xall`` (rows, on the stage's chart ``prm``): the
    forces (None: some point admits none) and its iterations."""
    m = stage.m
    guess = planned_force_guess(m, Xall, prm, load)
    torques = _torque_rows(stage, problem, Xall, prm, model_rows)
    F, iterations = stage.solve(Xall, prm, load, problem.object.length_scale, guess, torques)
    if F is None and torques is not None:
        # no forces within the actuators: the plan's forces without them (the actuator
        # check then refuses the plan, naming the joint), not the coupled NLP's
        F, more = stage.solve(Xall, prm, load, problem.object.length_scale, guess)
        iterations += more
    return F, iterations


def _model_torques(problem: ManipulationProblem, kin: ManipulationSolution, col: Any,
                   tips: Any) -> list[np.ndarray] | None:
    """Per fingertip (``tips``: the grasp model's), what the hand's own model needs at
    each of the plan's points (nodes, then midpoints; rows) on top of the contact forces'
    torques: its links' weight, the joints' damping and springs, the motion's inertia (MuJoCo's, the
    actuation's ``model_torques``, which the actuator check adds too); None where the
    actuation has no model (a URDF's)."""
    act = problem.actuation
    if act is None or not hasattr(act, "model_torques") or not problem.fingers:
        return None
    t_nodes = np.asarray(col.t_nodes, dtype=float)
    times = np.concatenate([t_nodes, (t_nodes[:-1] + t_nodes[1:]) / 2])
    try:
        smp = kin.sample(times)
        return [np.asarray(act.model_torques(t.finger.joint_names, smp.x[:, t.q_cols],
                                             smp.x_dot[:, t.q_cols],
                                             smp.x_ddot[:, t.q_cols]), dtype=float)
                for t in tips]
    except (ValueError, AssertionError):  # a joint the file does not name; no polynomials
        return None


def _torque_rows(stage: ForceStage, problem: ManipulationProblem, Xall: np.ndarray,
                 prm: np.ndarray, model: list[np.ndarray] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The force stage's torque rows for the problem's actuators (``problem.actuation``,
    :data:`ROLL_TORQUE_SHARE` of their ranges at each point's joints: a position servo's
    control range bounds its torque near the range's ends), less what the hand's model
    needs there (``model``, :func:`_model_torques`: the contact forces' torques plus that
    are what the actuators give, and what a passive joint's tendon must): their
    parameters at ``Xall`` and bounds (joints x points); None without actuators or
    limits."""
    if problem.actuation is None or problem.forces is None or not stage.tips:
        return None
    from ocp.robots.actuation import torque_bounds_at
    from ocp.robots.couplings import tendon_torque_bounds

    los, his = [], []
    for i, (_, t) in enumerate(stage.tips):
        lo, hi = tendon_torque_bounds(t.finger, *torque_bounds_at(
            problem.actuation, t.finger.joint_names, Xall[:, t.q_cols], ROLL_TORQUE_SHARE))
        if model is not None:
            lo, hi = lo - model[i], hi - model[i]
        los.append(lo.T)
        his.append(hi.T)
    lo, hi = np.vstack(los), np.vstack(his)
    if not (np.isfinite(lo).any() or np.isfinite(hi).any()):
        return None
    return stage.torque_params(Xall, prm, problem.forces.gravity), lo, hi


def with_earlier(sol: ManipulationSolution, earlier: ManipulationSolution
                  ) -> ManipulationSolution:
    """``sol`` with the work of an ``earlier`` plan it followed (its iterations and
    times) added to its statistics."""
    if sol.stats is None or earlier.stats is None:
        return sol
    a, b = sol.stats, earlier.stats
    stats = replace(a, iterations=a.iterations + b.iterations,
                    attempts=a.attempts + b.attempts, build_time=a.build_time + b.build_time,
                    solve_time=a.solve_time + b.solve_time,
                    certificate_time=a.certificate_time + b.certificate_time,
                    ipopt_time=a.ipopt_time + b.ipopt_time)
    return replace(sol, stats=stats)
