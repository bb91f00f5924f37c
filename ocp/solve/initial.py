"""A grasp's state at t = 0 from its problem: the object block's initial state, each
fingertip's initial contact coordinates, its joints by inverse kinematics."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ocp.geometry.grasp import force_angles
from ocp.robots.finger import PAPER_SEED, inverse_kinematics
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.spec.problem import ProblemError
from ocp.transcription.grasp_model import GraspModel

#: The initial grasp's inverse kinematics is accepted within this [m and rad]: it aims at
#: 1e-10, and a 4-joint finger's 6-D pose target, made from contact coordinates that its
#: own joints gave, can stall a little above (a roll of the gait turning the built-in hand's
#: searched grasp 90 deg about the palm's -x: the thumb at 6e-11 m and 4.7e-10 rad was
#: refused, and the whole request with it). The certificate checks the plan's closure.
IK_ACCEPT = 1e-8

__all__ = ["initial_state"]

FloatArray = NDArray[np.float64]


def initial_state(m: GraspModel, problem: ManipulationProblem) -> FloatArray:
    """The state at t = 0 of a problem's grasp (``m``: its model), the fingers' joints by
    inverse kinematics; ProblemError saying why the initial grasp is impossible
    (unreachable, outside the joint limits, not in force closure)."""
    x = np.zeros(m.nx)
    x[m.object.xs] = m.object.initial(problem)
    for tip in m.fingertips:
        x[tip.eta_cols] = tip.spec(problem).initial
    prm = m.params(np.asarray(problem.object.params, dtype=float), contact_charts(problem))
    out = m.cartesian(x, prm)
    R_pf, p_pf = np.asarray(out[2]), np.asarray(out[3])
    errs: list[tuple[str, str]] = []
    for i, c in enumerate(problem.fingers):
        seed = np.asarray(c.q_seed if c.q_seed is not None else
                          PAPER_SEED[: c.finger.nq], dtype=float)
        if len(seed) < c.finger.nq:
            seed = np.concatenate([seed, np.zeros(c.finger.nq - len(seed))])
        ik = inverse_kinematics(c.finger, R_pf[:, 3 * i:3 * i + 3], p_pf[:, i], seed)
        name = f"fingers[{i}].initial"
        if not (ik.converged or max(ik.position_error, ik.orientation_error) <= IK_ACCEPT):
            errs.append((name, f"the finger cannot reach the initial grasp: after "
                               f"inverse kinematics its pad is {ik.position_error:.3g} m "
                               f"and {ik.orientation_error:.3g} rad from it"))
        elif not ik.within_limits:
            errs.append((name, "the initial grasp needs joint angles outside the "
                               "finger's limits"))
        x[m.fingertips[i].q_cols] = ik.q
    pts, nrm = np.asarray(out[4]).T[None], np.asarray(out[5]).T[None]
    phi, _, onto = force_angles(pts, nrm)
    cone = math.atan(problem.mu)
    if m.n_contacts >= 2 and not (phi[0] < cone and onto[0]):
        errs.append(("fingers", f"the initial grasp is outside the friction cone (not in "
                                f"force closure): grasp angle "
                                f"{math.degrees(phi[0]):.2f} deg >= atan(mu) = "
                                f"{math.degrees(cone):.2f} deg, by "
                                f"{math.degrees(phi[0] - cone):.2f} deg"
                     if onto[0] else "the initial grasp's contacts cannot resist every "
                                     "wrench (grasp map not onto)"))
    if errs:
        raise ProblemError(errs)
    return x
