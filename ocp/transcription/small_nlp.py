"""The NLP of a grasp without path rows (one contact, no tracking: the object on the palm
alone), written out in SX (:func:`small_grasp_nlp`): the same variables, constraints,
order and objective as the blocks' (:mod:`ocp.transcription.phased_nlp`)."""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np

from ocp.spec.problem import PERIODIC
from ocp.transcription.blocks import ramp_penalty
from ocp.transcription.collocation import HermiteSimpson, target_residuals
from ocp.transcription.nlp_blocks import BlockNLP, _declaration

__all__ = ["small_grasp_nlp"]


def small_grasp_nlp(m: Any, segments: tuple[int, ...], goal_mask: tuple[bool, ...],
                     via_masks: tuple[tuple[bool, ...], ...], t0: float,
                     smooth: bool) -> BlockNLP:
    """The same NLP for a grasp without path rows (one contact, no tracking: the object
    on the palm alone), written out in SX: at this size one SX graph is cheaper to call
    than mapped blocks, and the rolling equations at a node shared by two intervals are
    evaluated once. Same variables, constraints, order and objective as the blocks'."""
    hs = HermiteSimpson(m.nx, m.nu, segments, smooth)
    n, nseg = hs.n_intervals, len(segments)
    decl = _declaration(m, nseg, len(via_masks), 2 * n + 1, False)
    p = ca.SX.sym("p", decl.size)
    prm = decl.unpack(p)
    shape_p, seg_T, goal, vias = prm["shape"], prm["seg_T"], prm["goal"], prm["vias"]
    L, T = m.surface.length_scale(shape_p), ca.sum1(prm["seg_T"])
    x_scale = ca.vertcat(*m.x_scale(L))
    u_scale = ca.vertcat(*m.u_scale(L, T))
    params = ca.vertcat(shape_p, prm["charts"])
    g = [hs.defects(m.dynamics, params, x_scale, u_scale, seg_T)]
    ends = hs.segment_end_nodes
    for j, vmask in enumerate(via_masks):
        g += target_residuals(hs.X[:, ends[j]], vias[:, j], vmask, x_scale, PERIODIC)
    g += target_residuals(hs.X[:, ends[-1]], goal, goal_mask, x_scale, PERIODIC)
    g_all = ca.vertcat(*g)
    xs, us, wq = ca.SX.sym("xs", m.nx), ca.SX.sym("us", m.nu), ca.SX.sym("wq", 3)
    effort: Any = ca.SX(0)
    for k, idx in enumerate(m.effort_groups()):
        if idx:
            effort += wq[k] * ca.sumsqr(us[idx])
    effort_fn = ca.Function("effort", [xs, us, wq], [effort])
    weights = prm["weights"][0:3]
    f = hs.simpson(lambda x, u: effort_fn(x, u, weights), seg_T / T)
    if smooth:  # the ramps' term (see build_manipulation_nlp)
        ramp = prm["accel"][1]
        hns = hs.steps(seg_T / T)
        for k in range(n):
            for j, idx in enumerate(m.effort_groups()):
                if idx:
                    f += weights[j] * ramp ** 2 * ramp_penalty(
                        hs.U[idx, hs.left_cols[k]], hs.Um[idx, k], hs.U[idx, hs.right_cols[k]],
                        hns[k])
    w = hs.w
    empty = [ca.SX(0, n + 1), ca.SX(0, n), ca.SX(0, 2 * n + 1)]
    unpack = ca.Function("unpack", [w], [hs.X, hs.Xm, hs.U, hs.Um, *empty])
    pack = ca.Function("pack", [hs.X, hs.Xm, hs.U, hs.Um, *empty], [w])
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g_all.numel())
    oracle = ca.Function("manipulation_nlp", [w, p], [f, g_all], ["x", "p"], ["f", "g"])
    jac_g = ca.Function("nlp_jac_g", [w, p], [g_all, ca.jacobian(g_all, w)], ["x", "p"],
                        ["g", "jac_g_x"])
    hess = ca.triu(ca.hessian(lam_f * f + ca.dot(lam_g, g_all), w)[0])
    hess_lag = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess],
                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    zeros = np.zeros(g_all.numel())
    return BlockNLP(hs, unpack, pack, decl, zeros, zeros.copy(), time.perf_counter() - t0,
                    0, 0, oracle, jac_g, hess_lag, 0)
