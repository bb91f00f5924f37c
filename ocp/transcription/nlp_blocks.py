"""The manipulation NLP from small blocks: per-point and per-interval CasADi functions.

A grasp's direct-collocation NLP (:mod:`ocp.solve.planner`) has the same few functions at
every collocation point (force closure, tracking: the finger's forward kinematics and the
contact geometry; the fingertips' closure at the velocity level) and in every interval
(the Hermite-Simpson defects of the rolling equations, the effort and grasp terms of the
objective). Written out in SX at every point,
the NLP of the paper's experiment 1 (palm + one 6-joint finger, N = 60) took 2.7 s to
build, held ~220 MB, and its generated C (72 MB) was beyond gcc. Here each block is one SX
function of its own variables; its Jacobian and the Hessian of its Lagrangian are
differentiated once, at the block's own dimension, and applied to every point or interval
with ``Function.map``; the NLP's constraint Jacobian and Lagrangian Hessian are assembled
from the blocks' nonzeros by a constant sparse matrix (:class:`BlockAssembler`) and given to
IPOPT as ``jac_g`` and ``hess_lag``. Same NLP (same variables, constraints, order, bounds;
the same plan to round-off), built in a fraction of a second, ~20 MB, and small enough to
compile (``compile_dir``: a few MB of C, seconds of gcc).

Why not let CasADi differentiate an MX NLP of mapped functions: its coloring over the whole
NLP calls every block's derivatives in as many directions as the widest block couples
(16 for the Jacobian, 12 for the Hessian of experiment 1), mostly zeros for any one block:
IPOPT took 3.2x longer. ``expand=True`` turns it back into the SX NLP.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.transcription.collocation import HermiteSimpson
from ocp.transcription.loads import (
    LOAD_PARAMS,
    LOAD_PUSH_WEIGHT,
    LOAD_REGULARISATION,
    LOAD_VARS,
    TORSION_SHARE,
    load_cost,
    load_rows,
)
from ocp.transcription.parameters import Parameters

__all__ = ["LOAD_PARAMS", "LOAD_PUSH_WEIGHT", "LOAD_REGULARISATION", "LOAD_VARS",
           "TORSION_SHARE", "BlockAssembler", "BlockNLP", "Schedule", "build_manipulation_nlp",
           "interval_touching", "load_cost", "load_rows"]

#: A grasp's contact phases on its grid: (intervals, which fingertips touch the object) per
#: phase, in time order; None: one phase, every fingertip touching.
Schedule = tuple[tuple[int, tuple[bool, ...]], ...]


def _node_input_pairs(hs: HermiteSimpson, free_ends: bool = False) -> list[tuple[int, int]]:
    """(node, input column) of every input at a node that is not fixed: each interval's
    start, and each segment's end (with the paper's timing a via-point node has the input
    arriving and the one leaving). With the smooth timing (continuous inputs) each node
    has one input, and the first and last are fixed at rest (zero: rows in them would be
    identically zero)."""
    lc, rc = hs.left_cols, hs.right_cols
    ends = [int(k) for k in np.cumsum(hs.segments)]
    pairs = [(k, lc[k]) for k in range(hs.n_intervals)] + [(k, rc[k - 1]) for k in ends]
    if hs.continuous and not free_ends:  # (``free_ends``: a window's, moving)
        pairs = [pc for pc in dict.fromkeys(pairs)
                 if pc not in ((0, lc[0]), (hs.n_intervals, rc[-1]))]
    return pairs

FloatArray = NDArray[np.float64]


@dataclass
class BlockNLP:
    """One grasp structure's NLP as functions: its variables' layout, parameters,
    constraint bounds, and the problem with its block-assembled derivatives (the solver is
    made from them by :func:`ocp.solve.ipopt.ipopt_solver`)."""

    hs: HermiteSimpson  # SX symbols of the grid: columns, pack/unpack of the states/inputs
    unpack: ca.Function
    pack: ca.Function
    #: the parameter vector's declaration, by name
    #: (:class:`~ocp.transcription.parameters.Parameters`)
    params: Parameters
    lbg: FloatArray
    ubg: FloatArray
    build_time: float
    n_force: int  # contacts with internal-force variables (0 for two contacts)
    n_epigraph: int  # grasp-angle epigraph variables per point (0 for one contact)
    #: the problem as a function (w, p) -> (f, g), its constraints' Jacobian and the
    #: Hessian of its Lagrangian (upper triangle), assembled from the blocks
    oracle: ca.Function
    jac_g: ca.Function
    hess_lag: ca.Function
    #: contacts with planned load forces (:data:`LOAD_VARS` variables each at every
    #: point, after the internal forces in ``F``; 0 without ``forces``)
    n_load: int = 0
    #: variables no row or cost of their point's phase uses (a lifted fingertip's contact
    #: coordinates and contact inputs, the forces of contacts that do not touch): fixed
    #: at zero by the bounds (:func:`~ocp.transcription.values.bounds`); empty for one phase
    parked: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: each interval's fingertips touching the object (the schedule, per interval)
    touching: tuple[tuple[bool, ...], ...] = ()
    #: the stage order's copies of each interval's end (``stage_order``; free variables,
    #: the gap-closing rows tie them; :mod:`~ocp.transcription.stage_order`): empty in
    #: the kind order
    copies: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: the stages' sizes in the stage order (fatrop's ``N``, ``nx``, ``nu``, ``ng``); None
    #: in the kind order
    stages: dict[str, Any] | None = None

    def aux_indices(self) -> NDArray[np.int64]:
        """The variables other than the states and inputs (epigraph, forces, copies):
        what a warm start takes from a previous NLP point (computed once)."""
        cached = self.__dict__.get("_aux")
        if cached is not None:
            return cached
        self.__dict__["_aux"] = self._aux_indices()
        return self.__dict__["_aux"]

    def _aux_indices(self) -> NDArray[np.int64]:
        Xi, Xmi, Ui, Umi = (np.asarray(a).ravel() for a in
                            self.unpack(np.arange(self.pack.nnz_out(0), dtype=float))[:4])
        xu = np.concatenate([Xi, Xmi, Ui, Umi]).round().astype(np.int64)
        return np.setdiff1d(np.arange(self.pack.nnz_out(0)), xu)


class BlockAssembler:
    """A global sparse matrix from the concatenated nonzeros of many blocks.

    ``rows``/``cols``: the global position of every block nonzero, in the order the blocks'
    nonzero vectors are concatenated; entries at the same position are summed, entries with
    a negative row dropped; ``symmetric`` maps each entry to the upper triangle. Calling it
    on the nonzeros (an MX column) gives the MX matrix (one constant sparse product)."""

    def __init__(self, shape: tuple[int, int], rows: NDArray[np.int64],
                 cols: NDArray[np.int64], symmetric: bool = False) -> None:
        keep = rows >= 0
        r, c = rows, cols
        if symmetric:
            r, c = np.minimum(rows, cols), np.maximum(rows, cols)
        lin = c[keep].astype(np.int64) * shape[0] + r[keep]
        uniq, inv = np.unique(lin, return_inverse=True)  # column-major = CCS order
        self.sparsity = ca.Sparsity.triplet(shape[0], shape[1], (uniq % shape[0]).tolist(),
                                            (uniq // shape[0]).tolist())
        src = np.flatnonzero(keep)
        self.matrix = ca.DM(ca.Sparsity.triplet(len(uniq), len(rows), inv.tolist(),
                                                src.tolist()), 1.0)

    def __call__(self, nz: Any) -> Any:
        return ca.MX(self.sparsity, ca.mtimes(self.matrix, nz))


def _declaration(m: Any, nseg: int, nv: int, npts: int, tracking: bool,
                 reference: bool = False, switch: bool = False) -> Parameters:
    """The NLP's parameters, by name (every structure's, whatever it uses; with a chart
    ``switch`` the next chart's patches and the switch's reference angles,
    :mod:`~ocp.transcription.chart_switch`)."""
    n_track = npts if tracking else 0
    n_ref = npts if reference else 0
    return Parameters.of(shape=(m.surface.n_params, 1), seg_T=(nseg, 1), goal=(5, 1),
                         vias=(5, nv), charts=(9 * m.n_contacts, 1), weights=(6, 1),
                         ccone=(1, 1), tol=(2, 1), Pd=(3, n_track), Rd=(9, n_track),
                         load=(LOAD_PARAMS, 1), accel=(2, 1), Xr=(m.nx, n_ref),
                         Wr=(1, n_ref), Qx=(m.nx if reference else 0, 1),
                         Ur=(3 * m.nu, (npts - 1) // 2 if reference else 0),
                         wu=(1 if reference else 0, 1),
                         charts_b=(9 * m.n_contacts if switch else 0, 1),
                         switch_refs=(2 * len(m.fingertips) if switch else 0, 1))


def _triplets(sp: ca.Sparsity) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    r, c = sp.get_triplet()
    return np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64)




def interval_touching(n_fingertips: int, n: int, schedule: Schedule | None
                      ) -> list[tuple[bool, ...]]:
    """Which fingertips touch the object on each of the ``n`` intervals."""
    if schedule is None:
        return [(True,) * n_fingertips] * n
    out: list[tuple[bool, ...]] = []
    for k, mask in schedule:
        if k < 1 or len(mask) != n_fingertips:
            raise ValueError(f"a phase needs at least one interval and one flag per "
                             f"fingertip ({n_fingertips}), got {k} and {len(mask)}")
        out += [tuple(bool(t) for t in mask)] * k
    if len(out) != n:
        raise ValueError(f"the phases span {len(out)} intervals, the grid has {n}")
    return out


def build_manipulation_nlp(m: Any, segments: tuple[int, ...], goal_mask: tuple[bool, ...],
                           via_masks: tuple[tuple[bool, ...], ...], tracking: bool,
                           force_regularisation: float, small: bool | None = None,
                           forces: bool = False, smooth: bool = False,
                           schedule: Schedule | None = None,
                           stage_order: bool = False, reference: bool = False,
                           switch: Any = None) -> BlockNLP:
    """The NLP of one grasp structure (``m``: its
    :class:`~ocp.transcription.grasp_model.GraspModel`) with its contact phases
    (``schedule``: :data:`Schedule`; None, one phase with every fingertip touching):
    variables ``w = (X, Xm, U, Um, S, Sm, F)`` (scaled states and inputs at
    nodes and midpoints, grasp epigraph at every point, internal forces of 3+ contacts),
    parameters ``p = (shape, seg_T, goal, vias, charts, weights, cone cosine, tracking
    tolerances, desired positions, desired rotations)``; constraints: the defects of every
    interval, every point's path constraints (node 0, the given initial grasp, without its
    tracking bounds), the goal and via-point targets, the fingertips' closure at the
    velocity level at every node (with each of its inputs) and midpoint, the joints'
    accelerations, the closure of fingertips landing at a node. ``small`` (default: for
    one contact without tracking) writes the same NLP out in SX instead of from blocks.

    Phases share one grid and one layout of the variables; each interval and point gets
    the blocks of its phase (:mod:`ocp.transcription.blocks`: built from what the phase's
    active contacts contribute, once per distinct set of touching fingertips): a node
    between two phases has the contacts of both (a fingertip lifts off after it, lands
    on it). A lifted fingertip's contact coordinates have no dynamics (they are not states
    of the phase) and its contact inputs drive nothing: both are parked (``parked``), as
    the forces of the contacts a point does not have; where it lands, its closure holds
    (:func:`~ocp.transcription.blocks.touchdown_block`).

    ``forces``: every contact's force at every point too (docs/forces.md): variables
    ``F``'s last ``LOAD_VARS * n_contacts`` rows, the object's quasi-static equilibrium
    with its weight, the friction cones with a margin, the minimum normal force, the
    soft-finger torsion within its limit; the load parameters ``load``.
    ``smooth`` (the smooth timing, docs/timing.md): one input per node, also at via-points
    (every velocity continuous), the first and last fixed at rest by their bounds
    (:func:`~ocp.transcription.values.bounds`), every joint's acceleration within the
    parameter ``accel[0]`` [rad/s^2] at both ends of every interval (the input is quadratic
    on an interval, its derivative linear: the ends bound it), the last rows; and each
    effort term has a ramp term, its weight times ``accel[1]^2`` times the integral of the
    squared rate of change of its inputs (``accel[1]``: the ramps' time constant over the
    duration). Without that term, continuity alone would let the optimum ramp up within
    one interval: a velocity jump again as h -> 0 (slip converged like h on the triangle
    example).

    ``reference`` (:class:`~ocp.spec.reference.Reference`): the tracking terms of a
    reference trajectory (parameters ``Xr``, ``Wr``: the scaled reference state and its
    weight at every point, ``Qx`` each state's weight; ``Ur``: the scaled reference inputs
    of every interval, ``wu`` their weight), and the first and last inputs free (a
    window of a longer motion starts and ends moving: the closure at the velocity level
    at the first and last nodes with them); never the small SX form.

    ``stage_order`` (issue 27): the same NLP laid out stage by stage for a
    structure-exploiting solver (:mod:`~ocp.transcription.stage_order`: each interval's
    end copied into its stage, the gap-closing rows first in each stage; ``copies`` and
    ``stages`` say where); never the small SX form.
    ``switch`` (:class:`~ocp.transcription.chart_switch.ChartSwitch`): the fingertips'
    contacts change chart at a node (parameters ``charts_b``, ``switch_refs``); never the
    small SX form."""
    t0 = time.perf_counter()
    nc = m.n_contacts
    hs = HermiteSimpson(m.nx, m.nu, segments, smooth)
    n = hs.n_intervals
    touching = interval_touching(len(m.fingertips), n, schedule)
    one_phase = len(set(touching)) == 1 and all(touching[0])
    if small is None:
        small = nc < 2 and not tracking and one_phase and not stage_order and not reference \
            and switch is None
    if small:
        if nc >= 2 or tracking or forces or not one_phase or stage_order or reference \
                or switch is not None:
            raise ValueError("only a grasp without path rows (one contact, no tracking, "
                             "one phase, kind order) has the small SX form")
        from ocp.transcription.small_nlp import small_grasp_nlp

        return small_grasp_nlp(m, segments, goal_mask, via_masks, t0, smooth)
    from ocp.transcription.phased_nlp import PhasedNLP

    return PhasedNLP(m, hs, touching, goal_mask, via_masks, tracking, force_regularisation,
                      forces, smooth, stage_order, reference, switch).build(t0)
