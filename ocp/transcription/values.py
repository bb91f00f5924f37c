"""A problem's values in its NLP: the variables' scales and bounds, the parameter vector
(the structure's NLP, :mod:`ocp.transcription.nlp_blocks`, has only symbols)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.geometry.grasp import cone_cosine
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.spec.problem import CONTACT_COORDS, ForceSpec
from ocp.transcription.collocation import node_times
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.nlp_blocks import LOAD_PARAMS, LOAD_VARS, TORSION_SHARE, BlockNLP

__all__ = ["TRACKING_BOUND_SHRINK", "bounds", "force_scale", "load_bounds", "load_parameters",
           "parameters", "scales"]

#: The friction cone's smoothing: mu_m f_n >= sqrt(|f_t|^2 + eps^2) with eps this fraction
#: of the minimum normal force's cone radius mu_m f_min: smooth at f_t = 0 (curvature
#: 1 / eps), never looser than the cone, and at f_n = f_min still 97 % of its radius.
CONE_SMOOTHING = 0.25
#: Bound of every planned force component, in units of the force scale.
LOAD_BOUND = 20.0

FloatArray = NDArray[np.float64]

#: Tracking bounds are imposed in the NLP at this fraction of the requested tolerance, so
#: that the motion between collocation points stays inside the tolerance itself.
TRACKING_BOUND_SHRINK = 0.95


def scales(problem: ManipulationProblem, m: GraspModel) -> tuple[FloatArray, FloatArray]:
    """Scales of the states and inputs (the object's size, the horizon)."""
    L, T = problem.object.length_scale, problem.duration
    return (np.asarray(m.x_scale(L), dtype=float),
            np.asarray(m.u_scale(L, T), dtype=float))

def force_scale(problem: ManipulationProblem) -> float:
    """The planned forces' scale [N]: the weight, or the grip of all contacts if larger."""
    return 1.0 if problem.forces is None else \
        float(load_vector(problem.forces, problem.mu, problem.n_contacts)[5])


def load_bounds(n_load: int, k: int) -> FloatArray:
    """The symmetric bound of the planned forces' variables of ``n_load`` contacts at ``k``
    points (``LOAD_VARS * n_load`` x k, scaled): every force component within
    :data:`LOAD_BOUND`, the torsion's share of its limit (each contact's last variable)
    within :data:`~ocp.transcription.nlp_blocks.TORSION_SHARE`."""
    bound = np.full((LOAD_VARS * n_load, k), LOAD_BOUND)
    bound[LOAD_VARS - 1::LOAD_VARS] = TORSION_SHARE
    return bound


def load_parameters(problem: ManipulationProblem) -> FloatArray:
    """The NLP's load parameters (:data:`~ocp.transcription.nlp_blocks.LOAD_PARAMS`)."""
    return load_vector(problem.forces, problem.mu, problem.n_contacts)


def load_vector(fs: ForceSpec | None, mu: float, n_contacts: int) -> FloatArray:
    """:func:`load_parameters` of a grasp of ``n_contacts`` contacts with the planned
    forces ``fs`` and the friction coefficient ``mu`` (no problem needed)."""
    if fs is None:
        return np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0])
    weight = fs.mass * np.asarray(fs.gravity, dtype=float)
    mu_m = math.tan(math.atan(mu) - fs.cone_margin)
    F0 = max(fs.mass * float(np.linalg.norm(fs.gravity)), n_contacts * fs.min_normal_force,
             1e-6)
    out = np.array([*weight, fs.min_normal_force, fs.torsional_friction, F0, mu_m,
                    CONE_SMOOTHING * mu_m * fs.min_normal_force / F0])
    assert out.size == LOAD_PARAMS
    return out


def parameters(problem: ManipulationProblem, nlp: BlockNLP,
               scales_: tuple[FloatArray, FloatArray] | None = None,
               switch: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """The NLP parameter vector of a problem (its structure's NLP ``nlp``): object,
    segment durations, palm goal and via-points, charts, weights, cone, tracking
    tolerances and the desired poses at every collocation point; with a reference, its
    states and inputs scaled by ``scales_`` (:func:`scales`: the grasp's states', inputs');
    with a chart switch, ``switch``: the next chart's patches (9 per contact, column-major)
    and the switch's reference angles (:mod:`~ocp.transcription.chart_switch`)."""
    segments, tb = problem.segments()
    t_nodes = node_times(segments, tb)
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    charts = contact_charts(problem)
    shape = np.asarray(problem.object.params, dtype=float)
    L = problem.object.length_scale
    goal = np.zeros(5)
    vias = np.zeros((5, 0))
    if problem.palm is not None:
        goal = np.array([problem.palm.goal.get(c, 0.0) for c in CONTACT_COORDS])
        vias = np.array([[vp.coords.get(c, 0.0) for c in CONTACT_COORDS]
                         for vp in problem.palm.via_points]).T.reshape(5, -1)
    tr = problem.tracking
    weights = [problem.object_effort_weight, problem.finger_effort_weight,
               problem.joint_effort_weight, problem.grasp_weight, tr.position_weight,
               tr.orientation_weight]
    tol = [1e6 if tr.position_tolerance is None else
           (TRACKING_BOUND_SHRINK * tr.position_tolerance / L) ** 2,
           1e6 if tr.orientation_tolerance is None else
           1 - math.cos(TRACKING_BOUND_SHRINK * tr.orientation_tolerance)]
    if problem.motion is not None:
        Rd, Pd = problem.motion.at(np.concatenate([t_nodes, tm]))
        Pd_, Rd_ = Pd.T, Rd.transpose(0, 2, 1).reshape(-1, 9).T  # column-major vec
    else:
        Pd_, Rd_ = np.zeros((3, 0)), np.zeros((9, 0))
    return nlp.params.pack(
        shape=shape, seg_T=np.diff(tb), goal=goal, vias=vias,
        charts=np.concatenate([R.ravel(order="F") for R in charts]), weights=weights,
        ccone=[cone_cosine(problem.mu)], tol=tol, Pd=Pd_, Rd=Rd_,
        load=load_parameters(problem),
        accel=[problem.max_joint_acceleration, problem.ramp_time_fraction],
        charts_b=np.zeros(0) if switch is None else switch[0],
        switch_refs=np.zeros(0) if switch is None else switch[1],
        **reference_parameters(problem, t_nodes, scales_))


def reference_parameters(problem: ManipulationProblem, t_nodes: FloatArray,
                         scales_: tuple[FloatArray, FloatArray] | None
                         ) -> dict[str, Any]:
    """The reference's parameters (:class:`~ocp.spec.reference.Reference`; empty without
    one): the scaled states at every point (nodes, then midpoints) with each point's
    weight (Simpson's rule in normalised time, the last node's ``terminal_weight`` more),
    the scaled inputs of every interval (start, midpoint, end) and their weight."""
    ref = problem.reference
    if ref is None:
        return {k: np.zeros(0) for k in ("Xr", "Wr", "Qx", "Ur", "wu")}
    if scales_ is None:
        raise ValueError("a problem with a reference needs the grasp's scales "
                         "(parameters(problem, nlp, scales(problem, model)))")
    x_scale, u_scale = scales_
    n = len(t_nodes) - 1
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    xs, _ = ref.at(np.concatenate([t_nodes, tm]))
    hn = np.diff(t_nodes) / float(t_nodes[-1] - t_nodes[0])
    sw = np.concatenate([(np.r_[0.0, hn] + np.r_[hn, 0.0]) / 6, 4 * hn / 6])
    wr = ref.state_weight * sw
    wr[n] += ref.terminal_weight * ref.state_weight / n
    _, u0 = ref.at(t_nodes[:-1])
    _, um = ref.at(tm)
    _, u1 = ref.at(t_nodes[1:])
    Ur = np.vstack([(u0 / u_scale).T, (um / u_scale).T, (u1 / u_scale).T])
    qx = np.ones(len(x_scale)) if ref.state_weights is None else \
        np.asarray(ref.state_weights, dtype=float)
    return {"Xr": (xs / x_scale).T, "Wr": wr[None, :], "Qx": qx, "Ur": Ur,
            "wu": [ref.input_weight]}


def bounds(problem: ManipulationProblem, nlp: BlockNLP, m: GraspModel, x0: FloatArray,
           x_scale: FloatArray, u_scale: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) bounds of the NLP's variables: every contact's own (physical,
    scaled here), the fixed initial state, the epigraph in [0, 2], the internal forces,
    the parked variables (:attr:`~ocp.transcription.nlp_blocks.BlockNLP.parked`) at zero."""
    n = nlp.hs.n_intervals
    lo: list[float] = []
    hi: list[float] = []
    uhi: list[float] = []
    for c in m.contacts:  # physical bounds, scaled as the states and inputs
        lo_c, hi_c, uhi_c = c.bounds(problem)
        lo, hi, uhi = lo + lo_c, hi + hi_c, uhi + uhi_c
    xb_hi, xb_lo = np.array(hi) / x_scale, np.array(lo) / x_scale
    lo_x, hi_x = np.tile(xb_lo, (n + 1, 1)), np.tile(xb_hi, (n + 1, 1))
    lo_x[0] = hi_x[0] = x0 / x_scale
    lo_xm, hi_xm = np.tile(xb_lo, (n, 1)), np.tile(xb_hi, (n, 1))
    ub_in = np.array(uhi) / u_scale
    n_cols = nlp.hs.n_input_cols
    lo_u, hi_u = np.tile(-ub_in, (n_cols, 1)), np.tile(ub_in, (n_cols, 1))
    if nlp.hs.continuous and problem.reference is None:  # the smooth timing: at rest at
        # the start and at the end (a window of a longer motion, tracking its reference,
        # starts and ends moving)
        for col in (nlp.hs.left_cols[0], nlp.hs.right_cols[-1]):
            lo_u[col] = hi_u[col] = 0.0
    if problem.initial_input is not None:  # a moving start: the given input, either timing
        col = nlp.hs.left_cols[0]
        lo_u[col] = hi_u[col] = np.asarray(problem.initial_input, dtype=float) / u_scale
    lo_um, hi_um = np.tile(-ub_in, (n, 1)), np.tile(ub_in, (n, 1))
    ns = nlp.n_epigraph
    zeros_s, twos_s = np.zeros((ns, n + 1)), 2 * np.ones((ns, n + 1))
    big = np.vstack([1e3 * np.ones((3 * nlp.n_force, 2 * n + 1)),
                     load_bounds(nlp.n_load, 2 * n + 1)])
    lbx = np.asarray(nlp.pack(lo_x.T, lo_xm.T, lo_u.T, lo_um.T, zeros_s, zeros_s[:, :n],
                              -big)).ravel()
    ubx = np.asarray(nlp.pack(hi_x.T, hi_xm.T, hi_u.T, hi_um.T, twos_s, twos_s[:, :n],
                              big)).ravel()
    # what the phases do not use (a lifted fingertip's contact coordinates and inputs, the
    # forces of contacts that do not touch): parked at zero
    lbx[nlp.parked] = ubx[nlp.parked] = 0.0
    return lbx, ubx
