"""Rolling an object on a flat palm (the paper's eq. 8): the grasp pipeline's plan of the
object on the palm alone, in the ball-on-palm planner's terms.

State: the palm/object contact coordinates eta_p = (x, y, u, v, psi); input: the palm
contact velocity w = d/dt (x, y) [m/s]; objective: the control effort integral |w|^2 dt;
goals and via-points: equality constraints on any subset of eta. This is a one-contact
grasp (a :class:`~ocp.contacts.SupportContact` and no fingers) of the one formulation in
:mod:`ocp.solve.planner`: the same transcription (written out in SX at this size), the
same solve loop with the palm's strategies (simulated reference paths with loops for pure
reorientations, the gauge bound of the symmetric vertical case: :mod:`ocp.solve.guesses`),
the same certificate (:func:`ocp.solve.certify.certify_grasp`) with the palm's
tolerances. :class:`BallOnPalmPlanner` poses a :class:`~ocp.spec.problem.BallOnPalmProblem` as
that grasp and returns its plan as a :class:`~ocp.solution.Solution` (the contact
coordinates' trajectory, sampled on any grid, with the certificate under the
ball-on-palm names).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import PALM_TOLERANCES, Certificate
from ocp.contacts.palm_model import (
    NU,
    NX,
    BallOnPalmModel,
    contact_coordinates,
    model_for,
    object_pose,
)
from ocp.geometry.surfaces import rotation_from_vector
from ocp.solution import ManipulationSolution, Solution, SolverStats, Status, Trajectory
from ocp.solve import planner as _pipeline
from ocp.solve.certify import certify_grasp
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem, Palm
from ocp.spec.problem import (
    BallOnPalmProblem,
    ProblemError,
    Structure,
    coordinate_error,
    goal_errors,
    wrap_difference,
)
from ocp.transcription.collocation import WarmStart

__all__ = [
    "NU",
    "NX",
    "BallOnPalmModel",
    "BallOnPalmPlanner",
    "ProblemError",
    "Structure",
    "certify",
    "contact_coordinates",
    "coordinate_error",
    "goal_errors",
    "grasp_problem",
    "model_for",
    "object_pose",
    "plan",
    "wrap_difference",
]

FloatArray = NDArray[np.float64]

#: The grasp pipeline's check -> (the ball-on-palm certificate's name, its tolerance key),
#: in the order the ball-on-palm certificate lists them.
CHECK_NAMES = {
    "max_length_defect": ("max_position_defect", "position_defect"),
    "max_angle_defect": ("max_angle_defect", "angle_defect"),
    "max_slip_speed_palm": ("max_slip_speed", "slip_speed"),
    "max_spin_rate_palm": ("max_spin_rate", "spin_rate"),
    "max_height_error_palm": ("max_height_error", "height"),
    "max_goal_error": ("max_goal_error", "goal"),
}


def grasp_problem(problem: BallOnPalmProblem) -> ManipulationProblem:
    """The ball-on-palm problem as the one-contact grasp of the pipeline (the palm's
    defect tolerances)."""
    return ManipulationProblem(
        problem.object, (), problem.duration,
        palm=Palm(problem.initial, problem.goal, problem.via_points, problem.palm_half_extent,
                  problem.max_contact_speed),
        n_intervals=problem.n_intervals, pole_margin=problem.pole_margin,
        max_refinements=problem.max_refinements, options=problem.options,
        tolerances=PALM_TOLERANCES, timing=problem.timing, ramp_time=problem.ramp_time)


def palm_certificate(cert: Certificate) -> Certificate:
    """The grasp pipeline's certificate of the object on the palm alone under the
    ball-on-palm names (``max_position_defect``, ...; tolerance keys ``position_defect``,
    ...): the same checks, values and tolerances."""
    named = {c.name: c for c in cert.checks}
    checks = [replace(named[k], name=new, tolerance_key=key)
              for k, (new, key) in CHECK_NAMES.items() if k in named]
    checks += [c for c in cert.checks if c.name not in CHECK_NAMES]
    return Certificate(tuple(checks), cert.reported, cert.n_samples)


def certify(problem: BallOnPalmProblem, t_nodes: FloatArray, X: FloatArray, U0: FloatArray,
            Um: FloatArray, U1: FloatArray,
            planner: ManipulationPlanner | None = None) -> Certificate:
    """The certificate of any plan of a ball-on-palm problem (node times and states, each
    interval's inputs at its start, midpoint and end): the one the planner gives its own
    plans (the benchmark's peers are checked with it)."""
    grasp = grasp_problem(problem)
    general = planner or _DEFAULT.general
    m = general.model(grasp)
    prm = m.params(np.asarray(problem.object.params, dtype=float),
                   [rotation_from_vector(problem.object.chart_rotation)])
    traj = m.interpolant(np.asarray(t_nodes, dtype=float), X, U0, Um, U1, prm)
    return palm_certificate(certify_grasp(grasp, m, traj, prm, grasp.tolerances))


class BallOnPalmPlanner:
    """Plans an object rolled on the palm with the grasp pipeline (NLPs cached per
    structure in its :class:`~ocp.solve.planner.ManipulationPlanner`)."""

    def __init__(self, max_iter_per_guess: int = 300,
                 compile_dir: Path | None = None,
                 general: ManipulationPlanner | None = None) -> None:
        #: The pipeline; with ``compile_dir`` its NLPs are compiled with gcc and cached
        #: there (:mod:`ocp.solve.compiled`): slower to build the first time, faster to solve.
        self.general = general or ManipulationPlanner(compile_dir,
                                                      max_iter_per_guess=max_iter_per_guess)

    @property
    def max_iter_per_guess(self) -> int:
        """IPOPT iterations spent on one initial guess before the next one is tried."""
        return self.general.max_iter_per_guess

    def nlp_for(self, problem: BallOnPalmProblem) -> tuple[Any, bool]:
        """The NLP of this problem's structure, and whether it came from the cache."""
        return self.general.build(grasp_problem(problem))

    def solve(self, problem: BallOnPalmProblem,
              warm_start: Solution | WarmStart | None = None, *,
              certify: bool = True) -> Solution:
        """Plan; raises :class:`ProblemError` (before building anything) on bad input.

        ``warm_start``: a previous plan of a similar problem (or its ``warm_start``), tried
        first as the initial guess (the planner's own guesses follow if IPOPT does not
        converge from it). When IPOPT converges but the certificate finds the
        discretisation too coarse, the plan is re-solved on a grid twice as fine,
        warm-started from the coarse one, up to ``problem.max_refinements`` times.

        ``certify=False`` (for a plan that only seeds another planner's initial guess): no
        certificate and so no refinement; the plan is at best ``INACCURATE`` and its
        certificate's only failure says that it was not checked.
        """
        problem.validate()
        if isinstance(warm_start, WarmStart):
            errs = warm_start.errors("warm_start", NX, NU)
            if errs:
                raise ProblemError(errs)
        warm = warm_start.plan if isinstance(warm_start, Solution) else warm_start
        plan = self.general.solve(grasp_problem(problem), warm, certify=certify)
        return palm_solution(problem, plan)


def _trajectory(model: BallOnPalmModel, params: FloatArray, chart: FloatArray,
                t: FloatArray, eta: FloatArray, eta_dot: FloatArray, w: FloatArray
                ) -> Trajectory:
    """The returned polynomials' contact coordinates and their rates at times t, the
    palm contact's velocity w (the NLP's input) and the rolling velocity it implies."""
    m = len(t)
    R, pos, cp, cn, om = model.kinematics.map(m)(eta.T, w.T, params, np.tile(chart, m))
    return Trajectory(t=t, eta=eta, eta_dot=eta_dot, w=w, rolling_velocity=np.asarray(om).T,
                      object_position=np.asarray(pos).T,
                      object_rotation=np.asarray(R).T.reshape(m, 3, 3).transpose(0, 2, 1),
                      contact_point=np.asarray(cp).T, contact_normal=np.asarray(cn).T)


def palm_solution(problem: BallOnPalmProblem, plan: ManipulationSolution) -> Solution:
    """The pipeline's plan of the object on the palm alone as a ball-on-palm
    :class:`~ocp.solution.Solution`: its returned polynomials on the collocation grid, at
    the nodes, and at any times."""
    col = plan.collocation
    assert col is not None and plan.stats is not None
    model = model_for(problem.object.surface.name)
    params = np.asarray(problem.object.params, dtype=float)
    patch = plan.object_chart_rotation or problem.object.chart_rotation
    chart = rotation_from_vector(patch)
    t_nodes = col.t_nodes
    palm = plan.contacts[0]
    grid = _trajectory(model, params, chart, plan.t, palm.eta, palm.eta_dot, palm.w)
    node_rows = np.arange(0, len(plan.t), 2)  # nodes and midpoints alternate
    nodes = _trajectory(model, params, chart, t_nodes, palm.eta[node_rows],
                        palm.eta_dot[node_rows], palm.w[node_rows])

    def sampler(t: FloatArray) -> Trajectory:  # the pipeline's polynomials
        smp = plan.sample(t)
        return _trajectory(model, params, chart, smp.t, smp.x, smp.x_dot, smp.u)

    cert = palm_certificate(plan.certificate)
    status = plan.status
    o = problem.options
    message = {
        Status.SOLVED: "converged; certificate passed",
        Status.INACCURATE: "converged, but the certificate failed: "
                           + "; ".join(cert.failures) + " (refine n_intervals)",
        Status.INFEASIBLE: "IPOPT reports the goals locally infeasible from every initial "
                           "guess tried; the last iterate is returned",
        Status.ITERATION_LIMIT: f"iteration limit {o.max_iter} reached; the last iterate is "
                                "returned",
        Status.TIME_LIMIT: f"time limit {o.time_limit} s reached; the last iterate is "
                           "returned",
        Status.NUMERICAL_ERROR: f"IPOPT stopped with {plan.raw_status}; the last iterate is "
                                "returned",
    }.get(status, plan.message)
    s = plan.stats
    stats = SolverStats(raw_status=s.raw_status, iterations=s.iterations, attempts=s.attempts,
                        build_time=s.build_time, solve_time=s.solve_time,
                        certificate_time=s.certificate_time,
                        objective=s.objective * problem.object.length_scale ** 2
                        / problem.duration, cache_hit=s.cache_hit, refinements=s.refinements,
                        n_intervals=s.n_intervals, ipopt_time=s.ipopt_time)
    # the goals as the plan met them (in its patch: the same physical goals)
    goal_error = {k.removeprefix("palm."): v for k, v in plan.goal_error.items()}
    return Solution(status=status, message=message, stats=stats, grid=grid, nodes=nodes,
                    certificate=cert, goal_error=goal_error, _sampler=sampler, plan=plan,
                    chart_rotation=tuple(float(a) for a in patch))


#: The ball-on-palm NLP's pieces a peer transcription of the same problem re-uses (the
#: benchmarks' peers, planner_service/bench/peers.py), exported by ``ocp`` under these
#: names: the state's size, the palm contact's CasADi functions, the certificate of a plan.
PALM_NX = NX
palm_model = model_for
certify_palm_plan = certify

_DEFAULT = BallOnPalmPlanner(general=_pipeline.default_planner())


def default_planner() -> BallOnPalmPlanner:
    """The process-wide planner (its pipeline's NLP cache serves every kind of grasp)."""
    return _DEFAULT


def plan(problem: BallOnPalmProblem, warm_start: Solution | WarmStart | None = None
         ) -> Solution:
    """Plan with the process-wide planner (and its NLP cache); ``warm_start`` as in
    :meth:`BallOnPalmPlanner.solve`."""
    return _DEFAULT.solve(problem, warm_start)

