"""The stage order of a grasp's NLP (issue 27): its variables and rows laid out as an
optimal-control problem's stages, so that a structure-exploiting solver (fatrop's Riccati
recursion) can see them.

Stage ``k`` of the ``n`` intervals holds its *state* ``s_k`` (node ``k``'s state, the
input arriving at node ``k``, node ``k``'s epigraph variables) and its *controls* (the
input leaving node ``k`` when it is another column, the interval's midpoint state, input
and epigraph, the copy of ``s_k+1``, the force variables of node ``k`` and of the
midpoint); the last stage ``n`` holds ``s_n`` and node ``n``'s forces. The rows of
stage ``k``: first the gap-closing rows ``s_k+1 - copy_k = 0`` (identity on ``s_k+1``),
then every row of the interval and of node ``k`` and its midpoint.

Why the copy: Hermite-Simpson's defects read ``f(x_k+1, u_k+1)``, nonlinear in the next
state, and fatrop's stages are ``x_k+1 = F(x_k, u_k)`` (a gap-closing row may read the
next stage's state only through an identity, and the Lagrangian's Hessian must be
block-diagonal by stage). With the copy in stage ``k``'s controls, the interval's blocks
read the copy instead of ``s_k+1`` and every nonlinear row and cost term lies within one
stage: the same NLP with ``nx + nu + n_s`` variables and as many linear equality rows more
per interval, the same solution. Without copies (``copies=False``) the layout is a pure
permutation of the kind-ordered NLP (the interval rows then read ``s_k+1``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.transcription.blocks import Block, _block

__all__ = ["StageLayout", "copy_block", "stage_layout", "stage_rows"]

IntArray = NDArray[np.int64]


@dataclass
class StageLayout:
    """Where every variable sits in the stage order.

    ``order``: the extended kind-order index (the kind-ordered variables, then the copies)
    of every stage-ordered variable; ``pos``: its inverse; ``copy_src``: the kind-order
    variable each copy copies; ``copies``: the copies' stage-order positions;
    ``cx, cu, cs``: the copies of each interval's end state, end input and end epigraph
    (stage-order positions, one column per interval; empty without copies); ``stage_of``:
    the stage of every stage-ordered variable; ``nx, nu``: each stage's state and control
    sizes (``n + 1`` stages)."""

    order: IntArray
    pos: IntArray
    copy_src: IntArray
    copies: IntArray
    cx: IntArray
    cu: IntArray
    cs: IntArray
    stage_of: IntArray
    nx: list[int]
    nu: list[int]

    @property
    def size(self) -> int:
        return len(self.order)


def stage_layout(idx: tuple[IntArray, ...], Fi: IntArray, left_cols: list[int],
                 right_cols: list[int], nw: int, copies: bool = True) -> StageLayout:
    """The stage order of the kind-ordered variables ``idx = (X, Xm, U, Um, S, Sm)`` and
    ``Fi`` (index arrays, points as columns: nodes, then midpoints) of ``nw`` variables,
    with each interval's end copied into its stage when ``copies``."""
    Xi, Xmi, Ui, Umi, Si, Smi = idx
    n = Xi.shape[1] - 1
    lc, rc = left_cols, right_cols
    arriving = [lc[0]] + [rc[k - 1] for k in range(1, n + 1)]
    order: list[IntArray] = []
    stage: list[int] = []
    nx: list[int] = []
    nu: list[int] = []
    src: list[IntArray] = []
    n_copy = nx_copy = 0
    cols: list[IntArray] = []
    for k in range(n + 1):
        state = [Xi[:, k], Ui[:, arriving[k]], Si[:, k]]
        ctrl: list[IntArray] = []
        if k < n:
            if lc[k] != arriving[k]:
                ctrl.append(Ui[:, lc[k]])
            ctrl += [Xmi[:, k], Umi[:, k], Smi[:, k]]
            if copies:
                end = np.concatenate([Xi[:, k + 1], Ui[:, rc[k]], Si[:, k + 1]])
                nx_copy = len(end)
                ids = nw + n_copy + np.arange(nx_copy)
                n_copy += nx_copy
                src.append(end)
                cols.append(ids)
                ctrl.append(ids)
        ctrl.append(Fi[:, k])
        if k < n:
            ctrl.append(Fi[:, n + 1 + k])
        s, c = np.concatenate(state), np.concatenate(ctrl)
        nx.append(len(s))
        nu.append(len(c))
        order += [s, c]
        stage += [k] * (len(s) + len(c))
    order_a = np.concatenate(order).astype(np.int64)
    total = nw + n_copy
    if not np.array_equal(np.sort(order_a), np.arange(total)):
        raise AssertionError("the stage order must place every variable exactly once")
    pos = np.empty(total, dtype=np.int64)
    pos[order_a] = np.arange(total)
    copy_src = np.concatenate(src).astype(np.int64) if src else np.zeros(0, np.int64)
    copies_at = pos[nw + np.arange(n_copy)]
    nxs, nus, nss = Xi.shape[0], Ui.shape[0], Si.shape[0]
    cpos = pos[np.stack(cols, axis=1)] if cols else np.zeros((nx_copy, 0), np.int64)
    return StageLayout(order_a, pos, copy_src, copies_at, cpos[:nxs], cpos[nxs:nxs + nus],
                       cpos[nxs + nus:nxs + nus + nss], np.asarray(stage, dtype=np.int64),
                       nx, nu)


def stage_rows(row_stage: IntArray, gap: NDArray[np.bool_], n_stages: int
               ) -> tuple[IntArray, list[int]]:
    """The rows' stage order: each stage's gap-closing rows first, then its other rows,
    each group in its kind order. ``row_stage``: every row's stage (the first stage of
    the variables it reads); returns every row's new position and the number of
    non-gap-closing rows of each stage (fatrop's ``ng``)."""
    key = np.lexsort((np.arange(len(row_stage)), ~gap, row_stage))
    new = np.empty(len(row_stage), dtype=np.int64)
    new[key] = np.arange(len(row_stage))
    ng = np.bincount(row_stage[~gap], minlength=n_stages).astype(int).tolist()
    return new, ng


def copy_block(size: int) -> Block:
    """The gap-closing rows of one stage: ``z = (s_next, copy)``, rows ``s_next - copy``
    (equalities; their Jacobian is exactly +1 on ``s_next``, as fatrop reads it)."""
    z = ca.SX.sym("z", 2 * size)
    rows = z[:size] - z[size:]
    return _block("copy", z, [], rows, None, ca.SX.sym("lam", size), ca.SX.sym("sigma"),
                  [0.0] * size, [0.0] * size)
