"""Grasp quality and force closure for any number of contacts.

Condition (Murray, Li & Sastry, *A Mathematical Introduction to Robotic Manipulation*,
1994, chapter 5, sections 5.2 "Grasp statics" and 5.3 "Force-closure"): a grasp is force
closure if and only if the grasp map ``G`` is onto (surjective) and there is an *internal
force* ``f`` (``G f = 0``) strictly inside the friction cones. For two soft-finger contacts
this is Nguyen's (1988) condition that the segment between the contacts lies inside both
cones, i.e. the paper's ``max(Phi_1, Phi_2) < atan(mu)`` (``ocp/geometry/grasp.py``).

Definitions (contacts ``i = 1..n``: points ``p_i``, *outward* unit object normals ``n_i``,
one frame; a finger pushes along ``-n_i``, so its force ``f_i`` on the object must satisfy
``push_i = -n_i . f_i > 0``):

* **Generalised grasp angle** ``Phi* = inf max_i angle(f_i, -n_i)`` over internal forces
  of hard point contacts with friction (``sum_i f_i = 0``, ``sum_i p_i x f_i = 0``) with
  every ``f_i != 0``. Force closure iff ``Phi* < atan(mu)`` and ``G`` is onto (soft-finger
  ``G`` for two contacts, whose hard-finger ``G`` has rank 5; hard-finger for ``n >= 3``).
  ``Phi* >= pi/2`` means no pushing internal force exists (``feasible`` False).
* ``n = 2``: the internal force is unique up to scale, ``f_1 = -f_2 ∝ p_2 - p_1``, and
  ``Phi* = max(Phi_1, Phi_2)`` of the paper (when ``Phi_1 + Phi_2 <= pi``, always on a
  convex object; otherwise the opposite sign ``f_1 ∝ p_1 - p_2`` is the better one).
  Closed form.
* ``n >= 3``: numerically. For a fixed angle the internal forces inside the cones form a
  second-order cone, so ``Phi*`` is a quasi-convex minimum. With ``f = B z`` (``B`` an
  orthonormal basis of ``ker G``: equilibrium exact) and ``push_i = -n_i . f_i``:

  1. an LP, ``max t`` s.t. ``sum_i push_i = n``, ``push_i >= t``: is there an internal
     force loading every contact with at least ``PUSH_FLOOR`` (mean push 1)? If not, the
     LP's force is the witness (``Phi* >= pi/2`` when some push is <= 0);
  2. the smooth epigraph NLP (no acos)::

         min s   s.t.  sum_i push_i = n,   push_i - (1 - s) |f_i| >= 0,
                       push_i >= PUSH_FLOOR,   0 <= s <= 1

     with ``s* = 1 - cos Phi*`` (the paper's quality measure ``1 - cos Phi``,
     generalised). For each ``s`` its feasible set is convex and the sets are nested, so
     every KKT point is a global minimum; each block's KKT conditions are checked.

  ``PUSH_FLOOR`` keeps every contact loaded (``f_i = 0`` would satisfy any cone, and MLS
  needs the internal force strictly inside every cone): the result is an upper bound on
  ``Phi*``, exact unless the infimum needs a vanishing contact force (then off by
  O(PUSH_FLOOR) rad). Each phase solves the whole batch in one IPOPT call (an NLP of
  ``k`` independent blocks: the per-``n`` CasADi Function mapped over the batch, solvers
  cached per batch-size bucket); blocks that fail the KKT check (hard blocks hold back a
  batch: it shares one step length and barrier parameter) are solved again, warm, in
  chunks, then alone. Reported angles are the exact angles of the witness force.

``docs/force-closure.md`` has the derivation and the measured speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache, lru_cache
from typing import Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.grasp import grasp_angles_numeric
from ocp.geometry.surfaces import safe_norm

__all__ = [
    "PUSH_FLOOR",
    "RANK_TOL",
    "GraspQuality",
    "grasp_matrix",
    "grasp_qualities",
    "grasp_quality",
    "internal_force_residuals",
]

FloatArray = NDArray[np.float64]
Sym = Any

#: Smallest normal push of a contact, in units of the mean push (the NLP normalises
#: ``sum_i push_i = n``). Without it ``f_i = 0`` satisfies every cone, and a grasp whose
#: best internal force leaves a contact unloaded would pass although it is not force closure
#: (MLS: the internal force must be *strictly* inside every cone).
PUSH_FLOOR = 1e-3
#: ``G`` is onto when the smallest singular value of the dimensionless grasp map (moments
#: about the centroid, divided by the rms contact distance from it) exceeds this.
RANK_TOL = 1e-8
#: A grasp whose internal forces all have zero total push (``|P_ker G (-n)|^2`` below this;
#: the normals are unit) has no pushing internal force: e.g. coplanar contacts with one
#: normal. Its NLP would be infeasible; it is not handed to the solver.
_DEGENERATE_PUSH = 1e-10
#: Below this distance [in units of the length scale] two contacts are treated as one point.
_COINCIDENT = 1e-12
#: IPOPT tolerance (the equilibrium is exact by construction: f = B z, B a basis of ker G).
_IPOPT_TOL = 1e-9
#: Iteration limits of a whole batch, of a chunk of _CHUNK blocks and of a single sample
#: (the blocks that have not converged in one are solved again in the next).
_MAX_ITER_BATCH = 40
_CHUNK = 32
_MAX_ITER_CHUNK = 150
_MAX_ITER_SINGLE = 300
#: Per-block KKT check of the angle NLP: stationarity (relative to the multipliers),
#: complementarity and feasibility.
_KKT_STAT = 1e-7
_KKT_COMPL = 1e-9
_KKT_FEAS = 1e-9
#: Largest batch handed to one IPOPT call (bigger batches are split). Every batch size
#: has its own solver, expanded to one SX graph and kept (``_batch_solver``): at 1024 the
#: certificate of one four-finger plan (220 samples, a 256-block solver per phase) held
#: 72 MB more than at 64 and took longer (the Allegro-class plan: RSS +159 MB -> +86 MB,
#: wall 9.0 -> 7.7-8.2 s; 128: +118 MB; 32: +70 MB, 8.4 s; tools/hand_bench.py).
_MAX_BATCH = 64


# ---------------------------------------------------------------------------------------
# Grasp map
# ---------------------------------------------------------------------------------------

def grasp_matrix(points: ArrayLike, normals: ArrayLike, model: Literal["hard", "soft"] = "hard",
                 length_scale: float = 1.0) -> FloatArray:
    """The grasp map ``G``: contact forces -> object wrench ``(force; moment / length_scale)``.

    Moments are about the frame's origin. Per contact the columns are the world-frame force
    components ``f_i`` (3 columns, ``[I; p_i^ / L]``) and, for ``model="soft"``, the torsion
    about the normal, ``m_i = L t_i`` (1 column, ``[0; n_i]``: the torque scaled to a force
    by ``L``). Shape ``(6, 3n)`` (hard) or ``(6, 4n)`` (soft). With ``length_scale=1`` this
    is the plain ``G`` in SI units. MLS 1994, section 5.2 (there in contact frames; the
    range, hence onto-ness, is the same).
    """
    P = np.asarray(points, dtype=float)
    N = np.asarray(normals, dtype=float)
    if P.ndim != 2 or P.shape != N.shape or P.shape[1] != 3:
        raise ValueError(f"points and normals must both be (n, 3), got {P.shape}, {N.shape}")
    if not length_scale > 0.0:
        raise ValueError(f"length_scale must be > 0, got {length_scale}")
    return _grasp_matrices(P[None] / length_scale, N[None], model)[0]


def _grasp_matrices(q: FloatArray, normals: FloatArray, model: str) -> FloatArray:
    """Batched G (k, 6, 3n | 4n) of points q (k, n, 3) (moments of q x f, unscaled)."""
    if model not in ("hard", "soft"):
        raise ValueError(f"model must be 'hard' or 'soft', got {model!r}")
    k, n, _ = q.shape
    w = 3 if model == "hard" else 4
    G = np.zeros((k, 6, n, w))
    G[:, :3, :, :3] = np.eye(3)[None, :, None, :]
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    zero = np.zeros_like(x)
    # hat(q_i) rows
    hat = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                    np.stack([-y, x, zero], -1)], axis=1)            # (k, 3, n, 3)
    G[:, 3:, :, :3] = hat
    if model == "soft":
        G[:, 3:, :, 3] = normals.transpose(0, 2, 1)
    return G.reshape(k, 6, n * w)


def _centred(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Batch (k, n, 3): (points about their centroid / L, L (k,)), L the rms distance from
    the centroid (1 where all the points coincide)."""
    c = points - points.mean(axis=1, keepdims=True)
    L = np.sqrt(np.mean(np.sum(c * c, axis=2), axis=1))
    coincident = _COINCIDENT * np.maximum(1.0, np.max(np.abs(points), axis=(1, 2))) > L
    L = np.where(coincident, 1.0, L)
    q = np.where(coincident[:, None, None], 0.0, c / L[:, None, None])
    return q, L


def _sigma_min(points: FloatArray, normals: FloatArray) -> FloatArray:
    """(k,) smallest singular value of the dimensionless G (soft fingers for n <= 2)."""
    q, _ = _centred(points)
    n = points.shape[1]
    G = _grasp_matrices(q, normals, "soft" if n <= 2 else "hard")
    if G.shape[2] < 6:
        return np.zeros(len(points))
    return np.asarray(np.linalg.svd(G, compute_uv=False)[:, 5], dtype=float)


# ---------------------------------------------------------------------------------------
# Result
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class GraspQuality:
    """Generalised grasp angle of a grasp and its witness internal force.

    ``angle``: Phi* [rad], the largest angle between a witness contact force and the
    inward normal, minimised over internal forces (>= pi/2: no pushing internal force).
    ``contact_angles``: (n,) the witness's angle at each contact [rad].
    ``forces``: (n, 3) the witness internal force, normalised to ``sum_i -n_i . f_i = 1``
    (all zeros if no internal force with a positive total push exists).
    ``rank_ok``: G is onto (soft-finger G for two contacts, hard-finger for more).
    ``sigma_min``: smallest singular value of the dimensionless G (see ``grasp_matrix``,
    moments about the centroid over the rms contact distance from it).
    ``feasible``: a pushing internal force exists (``angle < pi/2``).
    ``solver_ok``: the witness passed the KKT check of the angle NLP, i.e. is optimal (up
    to PUSH_FLOOR); False means it is only the best internal force found (its angles are
    still exact, so ``force_closure`` stays a valid certificate when True). Always True for
    n <= 2 (closed form).
    """

    angle: float
    contact_angles: FloatArray
    forces: FloatArray
    rank_ok: bool
    sigma_min: float
    feasible: bool
    solver_ok: bool = True

    def margin(self, mu: float) -> float:
        """atan(mu) - Phi* [rad]: positive iff the cone condition holds."""
        return math.atan(mu) - self.angle

    def force_closure(self, mu: float) -> bool:
        """Force closure (MLS 1994, section 5.3): G onto and Phi* < atan(mu)."""
        return bool(self.rank_ok and self.feasible and self.margin(mu) > 0.0)


# ---------------------------------------------------------------------------------------
# Symbolic residuals (planner) — also the body of the numeric NLP
# ---------------------------------------------------------------------------------------

def internal_force_residuals(points: Sym, normals: Sym, forces: Sym, length_scale: Any
                             ) -> tuple[Sym, Sym, Sym]:
    """(equilibrium (6,), push (n,), norms (n,)) of contact forces, CasADi SX or MX.

    ``points``, ``normals``, ``forces`` are (3, n) (columns = contacts, one frame).
    ``equilibrium = [sum_i f_i; sum_i (p_i - c) x f_i / length_scale]`` with ``c`` the
    centroid of the points (O(1) when the forces are O(1) and ``length_scale`` is the size
    of the grasp, e.g. the ball's radius); ``push_i = -n_i . f_i``;
    ``norms_i = |f_i|`` (``safe_norm``: finite gradient at 0).

    The numeric solver uses exactly these with the normalisation ``sum push = n`` and
    ``push_i >= PUSH_FLOOR``; a planner adds ``equilibrium == 0``, ``sum(push) == n``,
    ``push_i >= PUSH_FLOOR`` (or a larger floor), ``push_i - cos(atan mu) norms_i >= 0``
    (the cones) and/or ``push_i - (1 - s) norms_i >= 0`` (quality epigraph,
    ``s >= 1 - cos Phi*``).
    """
    n = int(points.shape[1])
    if normals.shape[1] != n or forces.shape[1] != n:
        raise ValueError("points, normals and forces must all be (3, n)")
    c = ca.sum2(points) / n
    total_f = ca.sum2(forces)
    moment = 0
    push = []
    norms = []
    for i in range(n):
        f_i = forces[:, i]
        moment = moment + ca.cross(points[:, i] - c, f_i)
        push.append(-ca.dot(normals[:, i], f_i))
        norms.append(safe_norm(f_i))
    equilibrium = ca.vertcat(total_f, moment / length_scale)
    return equilibrium, ca.vertcat(*push), ca.vertcat(*norms)


# ---------------------------------------------------------------------------------------
# Numeric solver (n >= 3; works for n = 2 as well, used to check the closed form)
# ---------------------------------------------------------------------------------------

def _block_parts(n: int, m: int) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """(z, p, push, norms) of one sample: f = B z, p = [vec B (3n m); vec normals (3n)]."""
    z = ca.SX.sym("z", m)
    B = ca.SX.sym("B", 3 * n, m)
    nrm = ca.SX.sym("n", 3, n)
    f = ca.reshape(B @ z, 3, n)
    _, push, norms = internal_force_residuals(ca.SX.zeros(3, n), nrm, f, 1.0)
    return z, ca.vertcat(ca.vec(B), ca.vec(nrm)), push, norms


@cache
def _block_function(n: int, m: int, phase: str) -> ca.Function:
    """One sample's (cost, g) of x, p for a phase.

    ``"push"`` (an LP): x = [z; t], max t s.t. sum push = n, push_i >= t: the most evenly
    pushing internal force; t* >= PUSH_FLOOR iff the angle NLP is feasible, and its
    solution is a feasible start for it.
    ``"angle"``: x = [z; s], min s s.t. sum push = n, push_i - (1 - s) |f_i| >= 0,
    push_i >= PUSH_FLOOR, 0 <= s <= 1. For each s the feasible z form a convex set, nested
    in s: from any non-optimal feasible point the segment to an optimum is a first-order
    feasible descent direction, so every KKT point is a global minimum.
    """
    z, p, push, norms = _block_parts(n, m)
    v = ca.SX.sym("v")
    if phase == "push":
        cost, g = -v, ca.vertcat(ca.sum1(push) - n, push - v)
    else:
        cost, g = v, ca.vertcat(ca.sum1(push) - n, push - (1 - v) * norms, push - PUSH_FLOOR)
    return ca.Function(f"internal_force_{phase}_{n}_{m}", [ca.vertcat(z, v), p], [cost, g],
                       ["x", "p"], ["cost", "g"])


@cache
def _kkt_function(n: int, m: int) -> ca.Function:
    """The angle NLP's (gradient of the Lagrangian, g) of one sample, for the KKT check.

    CasADi's convention: L = cost + lam_g . g + lam_x . x.
    """
    blk = _block_function(n, m, "angle")
    x = ca.SX.sym("x", blk.size1_in(0))
    p = ca.SX.sym("p", blk.size1_in(1))
    lam_g = ca.SX.sym("lam_g", blk.size1_out(1))
    lam_x = ca.SX.sym("lam_x", blk.size1_in(0))
    cost, g = blk(x, p)
    grad = ca.gradient(cost + ca.dot(lam_g, g), x) + lam_x
    return ca.Function(f"internal_force_kkt_{n}_{m}", [x, p, lam_g, lam_x], [grad, g])


@lru_cache(maxsize=32)
def _batch_solver(n: int, m: int, k: int, phase: str, warm: bool = False) -> ca.Function:
    """IPOPT over k independent blocks (a block-diagonal KKT system), built once per
    (n, m, k, phase) from the (n, m) block mapped over the batch.

    The blocks of one IPOPT run share its step length and barrier parameter: the adaptive
    barrier (driven by the average complementarity) lets the easy blocks converge while a
    few hard ones lag; ``k = 1`` (the fallback for those) uses the monotone barrier, which
    is the more robust on single degenerate samples.
    """
    blk = _block_function(n, m, phase)
    X = ca.MX.sym("X", blk.size1_in(0), k)
    P = ca.MX.sym("P", blk.size1_in(1), k)
    cost, g = blk.map(k)(X, P)
    nlp = {"x": ca.vec(X), "p": ca.vec(P), "f": ca.sum2(cost), "g": ca.vec(g)}
    opts = {
        "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
        "ipopt.tol": _IPOPT_TOL, "ipopt.acceptable_tol": 1e-7,
        "ipopt.max_iter": (_MAX_ITER_SINGLE if k == 1 or phase == "push" else
                           _MAX_ITER_CHUNK if k == _CHUNK else _MAX_ITER_BATCH),
        "ipopt.mu_strategy": "monotone" if k == 1 else "adaptive",
        # exact bounds: the default relaxation (1e-8) is large against a floored contact's
        # push (PUSH_FLOOR) and would show in its angle
        "ipopt.bound_relax_factor": 0.0,
        # one SX graph: derivatives ~10x faster than through the MX map node
        "expand": True,
    }
    if warm:
        # from a previous run's primal-dual point: keep it (no push into the interior)
        opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                     **{f"ipopt.warm_start_{key}": 1e-9 for key in (
                         "bound_push", "bound_frac", "slack_bound_push", "slack_bound_frac",
                         "mult_bound_push")}})
    return ca.nlpsol(f"force_closure_{phase}_{n}_{m}x{k}{'w' if warm else ''}", "ipopt", nlp,
                     opts)


def _bucket(k: int) -> int:
    """Batch size the solver is built for (the batch is padded): powers of two up to 64,
    then multiples of 64, so that few solvers are ever built."""
    if k <= 64:
        return 1 << max(0, (k - 1).bit_length())
    return 64 * -(-k // 64)


def _contact_angles(forces: FloatArray, normals: FloatArray) -> FloatArray:
    """(..., n) exact angles between f_i and -n_i (pi/2 where f_i = 0)."""
    push = -np.sum(normals * forces, axis=-1)
    mag = np.linalg.norm(forces, axis=-1)
    c = np.divide(push, mag, out=np.zeros_like(push), where=mag > 0.0)
    return np.asarray(np.arccos(np.clip(c, -1.0, 1.0)), dtype=float)


def _solve_numeric(points: FloatArray, normals: FloatArray) -> list[GraspQuality]:
    """Phi* for a batch (k, n, 3), any n >= 2 (rank_ok and sigma_min of the hard-finger G).

    The samples whose hard-finger G is onto (the generic case) are solved together (an LP
    call and an NLP call, see _solve_group); samples with a rank-deficient G (e.g.
    collinear contacts) form one more group per null-space dimension. Batches above
    _MAX_BATCH are split.
    """
    k, n, _ = points.shape
    if k > _MAX_BATCH:
        return [g for j in range(0, k, _MAX_BATCH)
                for g in _solve_numeric(points[j:j + _MAX_BATCH], normals[j:j + _MAX_BATCH])]
    q, _ = _centred(points)
    _, sv, Vt = np.linalg.svd(_grasp_matrices(q, normals, "hard"))   # Vt (k, 3n, 3n)
    rank = np.sum(sv > RANK_TOL, axis=1)
    minus_n = -normals.reshape(k, 3 * n)
    F = np.zeros((k, n, 3))
    usable = np.zeros(k, dtype=bool)
    ok = np.ones(k, dtype=bool)
    for r_ in np.unique(rank):
        idx = np.flatnonzero(rank == r_)
        B = Vt[idx, r_:, :].transpose(0, 2, 1)                      # (kk, 3n, m) orthonormal
        F[idx], usable[idx], ok[idx] = _solve_group(B, normals[idx], minus_n[idx])
    ang = _contact_angles(F, normals)
    ang[~usable] = math.pi / 2
    phi = np.max(ang, axis=1)
    sig = sv[:, 5]
    return [GraspQuality(float(phi[j]), ang[j], F[j], bool(sig[j] > RANK_TOL), float(sig[j]),
                         bool(phi[j] < math.pi / 2), bool(ok[j])) for j in range(k)]


def _solve_group(B: FloatArray, normals: FloatArray, minus_n: FloatArray
                 ) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """Witness forces (kk, n, 3) (sum push = 1), usable and solver-ok flags for a group of
    samples sharing the null-space dimension m = B.shape[2].

    Phase 1, one batched LP: is there an internal force with every push >= PUSH_FLOOR?
    Phase 2, the angle NLP for those: one batched IPOPT call; every block is then checked
    for KKT (which, for this NLP, means optimal). The blocks of one IPOPT run share its
    step length and barrier parameter, so a few hard blocks (degenerate optima) can hold
    back the whole batch: the blocks that fail the check are solved again in chunks of
    _CHUNK, then one by one. Of all the internal forces met for a block, the one with the
    smallest largest angle is its witness (each is an exact internal force, so its angles
    are a valid certificate even when no solve converged: solver_ok is then False).
    """
    kk, n3, m = B.shape
    n = n3 // 3
    v = np.einsum("kam,ka->km", B, minus_n)     # coordinates of P_ker(-n); total push |v|^2
    total_push = np.sum(v * v, axis=1)
    live = total_push >= _DEGENERATE_PUSH       # else no internal force pushes at all
    F = np.zeros((kk, n, 3))
    ok = np.ones(kk, dtype=bool)
    if m == 0 or not np.any(live):
        return F, np.zeros(kk, dtype=bool), ok
    # CasADi vec() is column-major: vec(B) is B^T row-major; the (3, n) normals' vec is the
    # contact-major (n, 3) row-major
    par = np.concatenate([B.transpose(0, 2, 1).reshape(kk, n3 * m), normals.reshape(kk, n3)],
                         axis=1)
    # start: the inward normals projected on ker G, scaled to sum push = n
    z0 = v * (n / np.maximum(total_push, _DEGENERATE_PUSH))[:, None]

    # phase 1, LP
    x0 = np.concatenate([z0, _pushes(B, normals, z0).min(axis=1, keepdims=True) - 1e-2], axis=1)
    X, ok_lp, _, _ = _run(n, m, "push", x0, par, None, None, live, _bucket(kk))
    best = X[:, :m].copy()
    best_angle = _max_angle(B, normals, best)
    solvable = live & (_pushes(B, normals, best).min(axis=1) >= PUSH_FLOOR * (1 + 1e-9))

    # phase 2, angle NLP: batch, then chunks, then single samples
    if np.any(solvable):
        f0 = np.einsum("kam,km->ka", B, z0).reshape(kk, n, 3)
        cos0 = _pushes(B, normals, z0) / np.maximum(np.linalg.norm(f0, axis=2), 1e-300)
        s0 = np.clip(np.max(1.0 - cos0, axis=1) + 1e-2, 0.0, 1.0)
        x0 = np.concatenate([z0, s0[:, None]], axis=1)
        lbx = np.concatenate([np.full(m, -np.inf), [0.0]])
        ubx = np.concatenate([np.full(m, np.inf), [1.0]])
        todo = solvable.copy()
        # the chunks start from the batch's primal-dual point (warm), a single sample anew
        xw, lgw, lxw = x0.copy(), np.zeros((kk, 1 + 2 * n)), np.zeros((kk, m + 1))
        sizes = [size for size in (_CHUNK, 1) if size < _bucket(kk)]
        for size in [_bucket(kk), *sizes]:
            warm = size == _CHUNK
            for start in range(0, kk, size) if size < kk else [0]:
                part = np.zeros(kk, dtype=bool)
                part[start:start + size] = True
                part &= todo
                if not np.any(part):
                    continue
                idx = np.flatnonzero(part) if size < kk else np.arange(kk)
                X, _, lam_g, lam_x = _run(
                    n, m, "angle", (xw if warm else x0)[idx], par[idx], lbx, ubx, part[idx],
                    size, (lgw[idx], lxw[idx]) if warm else None)
                if size == _bucket(kk):
                    xw, lgw, lxw = X, lam_g, lam_x
                conv = part[idx] & _kkt_ok(n, m, X, par[idx], lam_g, lam_x)
                angle = _max_angle(B[idx], normals[idx], X[:, :m])
                better = part[idx] & (conv | (angle < best_angle[idx]))
                best[idx[better]] = X[better, :m]
                best_angle[idx[better]] = angle[better]
                todo[idx[conv]] = False
            if not np.any(todo):
                break
        ok[solvable] = ~todo[solvable]
    # the others keep the LP's force: right if the LP converged
    ok[live & ~solvable] = ok_lp
    f = np.einsum("kam,km->ka", B, best)
    push_tot = np.einsum("ka,ka->k", f, minus_n)
    usable = live & (push_tot > 0.0)
    F[usable] = (f[usable] / push_tot[usable, None]).reshape(-1, n, 3)
    return F, usable, ok


def _max_angle(B: FloatArray, normals: FloatArray, z: FloatArray) -> FloatArray:
    """(k,) largest contact angle of the internal forces f = B z."""
    k, n3, _ = B.shape
    f = np.einsum("kam,km->ka", B, z).reshape(k, n3 // 3, 3)
    return np.asarray(np.max(_contact_angles(f, normals), axis=1), dtype=float)


def _run(n: int, m: int, phase: str, x0: FloatArray, par: FloatArray,
         lbx: FloatArray | None, ubx: FloatArray | None, active: NDArray[np.bool_],
         size: int, lam0: tuple[FloatArray, FloatArray] | None = None) -> tuple[Any, ...]:
    """Solve the ``active`` blocks (rows of x0, par) in one IPOPT call built for ``size``
    blocks (the batch is padded with copies of the first active block; the rows returned
    for inactive blocks are meaningless), warm-started from multipliers ``lam0`` = (lam_g,
    lam_x) per row if given. Returns (X, success, lam_g, lam_x) per row."""
    k, nx = x0.shape
    rows = np.full(size, int(np.flatnonzero(active)[0]))
    rows[:k][active] = np.flatnonzero(active)
    ng = 1 + n if phase == "push" else 1 + 2 * n
    solver = _batch_solver(n, m, size, phase, lam0 is not None)
    warm = {} if lam0 is None else {"lam_g0": lam0[0][rows].ravel(),
                                    "lam_x0": lam0[1][rows].ravel()}
    sol = solver(x0=x0[rows].ravel(), p=par[rows].ravel(),
                 lbx=-np.inf if lbx is None else np.tile(lbx, size),
                 ubx=np.inf if ubx is None else np.tile(ubx, size),
                 lbg=np.tile(np.zeros(ng), size),
                 ubg=np.tile(np.concatenate([[0.0], np.full(ng - 1, np.inf)]), size), **warm)
    X = np.asarray(sol["x"]).reshape(size, nx)[:k]
    lam_g = np.asarray(sol["lam_g"]).reshape(size, ng)[:k]
    lam_x = np.asarray(sol["lam_x"]).reshape(size, nx)[:k]
    return X, bool(solver.stats()["success"]), lam_g, lam_x


def _kkt_ok(n: int, m: int, X: FloatArray, par: FloatArray, lam_g: FloatArray,
            lam_x: FloatArray) -> NDArray[np.bool_]:
    """Per block: is (X, lam_g, lam_x) a KKT point of the angle NLP (hence optimal)?"""
    k = len(X)
    grad, g = _kkt_function(n, m).map(k)(X.T, par.T, lam_g.T, lam_x.T)
    grad, g = np.asarray(grad).T, np.asarray(g).T
    scale = 1.0 + np.max(np.abs(lam_g), axis=1)
    stat = np.max(np.abs(grad), axis=1) <= _KKT_STAT * scale
    feas = (np.abs(g[:, 0]) <= _KKT_FEAS * n) & np.all(g[:, 1:] >= -_KKT_FEAS, axis=1)
    # inequalities g >= 0: lam_g <= 0, lam_g g = 0; bounds 0 <= s <= 1 on the last entry
    sign = np.all(lam_g[:, 1:] <= _KKT_COMPL, axis=1)
    compl = np.max(np.abs(lam_g[:, 1:] * g[:, 1:]), axis=1) <= _KKT_COMPL * scale
    s, ls = X[:, -1], lam_x[:, -1]
    bound = np.abs(np.where(ls < 0.0, ls * s, ls * (1.0 - s))) <= _KKT_COMPL * scale
    return np.asarray(stat & feas & sign & compl & bound)


def _pushes(B: FloatArray, normals: FloatArray, z: FloatArray) -> FloatArray:
    """(k, n) pushes -n_i . f_i of f = B z."""
    k, n3, _ = B.shape
    f = np.einsum("kam,km->ka", B, z).reshape(k, n3 // 3, 3)
    return np.asarray(-np.sum(normals * f, axis=2), dtype=float)


# ---------------------------------------------------------------------------------------
# Two contacts: closed form
# ---------------------------------------------------------------------------------------

def _two_contacts(points: FloatArray, normals: FloatArray, sig: float) -> GraspQuality:
    """Closed form: f_1 = -f_2 along the line of the contacts, Phi* = max(Phi_1, Phi_2)."""
    p1, p2 = points
    n1, n2 = normals
    rank_ok = sig > RANK_TOL
    d = p2 - p1
    scale = max(float(np.linalg.norm(p1)), float(np.linalg.norm(p2)), 1.0)
    if float(np.linalg.norm(d)) <= _COINCIDENT * scale:
        # one point: internal forces (f, -f); best f bisects -n1 and n2
        b = -n1 + n2
        nb = float(np.linalg.norm(b))
        u = b / nb if nb > 0.0 else _any_perpendicular(n1)
        F = np.stack([u, -u])
    else:
        phi1, phi2 = grasp_angles_numeric(p1, n1, p2, n2)
        u = d / np.linalg.norm(d)
        if phi1 + phi2 > math.pi:  # pulling along d: push with the opposite sign
            u = -u
        F = np.stack([u, -u])
    ang = _contact_angles(F, normals)
    phi = float(np.max(ang))
    push = float(-np.sum(normals * F))
    feasible = phi < math.pi / 2 and push > 0.0
    return GraspQuality(phi, ang, F / push if feasible else F, rank_ok, sig, feasible)


def _any_perpendicular(v: FloatArray) -> FloatArray:
    a = np.eye(3)[int(np.argmin(np.abs(v)))]
    w = np.cross(v, a)
    return np.asarray(w / np.linalg.norm(w), dtype=float)


# ---------------------------------------------------------------------------------------
# Public entry points
# ---------------------------------------------------------------------------------------

def _as_batch(points: ArrayLike, normals: ArrayLike) -> tuple[FloatArray, FloatArray]:
    P = np.asarray(points, dtype=float)
    N = np.asarray(normals, dtype=float)
    if P.ndim != 3 or P.shape != N.shape or P.shape[2] != 3:
        raise ValueError(f"points and normals must both be (k, n, 3), got {P.shape}, {N.shape}")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(N))):
        raise ValueError("points and normals must be finite")
    norms = np.linalg.norm(N, axis=2)
    if np.any(np.abs(norms - 1.0) > 1e-6):
        raise ValueError("normals must be unit vectors")
    return P, N / norms[..., None]


def grasp_quality(points: ArrayLike, normals: ArrayLike) -> GraspQuality:
    """Phi*, witness, rank of G for one grasp: points (n, 3), outward unit normals (n, 3)."""
    P = np.asarray(points, dtype=float)
    N = np.asarray(normals, dtype=float)
    return grasp_qualities(P[None], N[None])[0]


def grasp_qualities(points: ArrayLike, normals: ArrayLike) -> list[GraspQuality]:
    """``grasp_quality`` for a batch: points (k, n, 3), normals (k, n, 3).

    ``n >= 3``: one IPOPT call for the whole batch. ``n = 2``: closed form (the paper's
    grasp angles). ``n = 1``: no internal force (Phi* = pi/2, not feasible).
    """
    P, N = _as_batch(points, normals)
    k, n, _ = P.shape
    if k == 0:
        return []
    if n == 0:
        raise ValueError("a grasp needs at least one contact")
    if n == 1:
        sig = _sigma_min(P, N)
        return [GraspQuality(math.pi / 2, np.array([math.pi / 2]), np.zeros((1, 3)),
                             False, float(sig[j]), False) for j in range(k)]
    if n == 2:
        sig = _sigma_min(P, N)
        return [_two_contacts(P[j], N[j], float(sig[j])) for j in range(k)]
    return _solve_numeric(P, N)
