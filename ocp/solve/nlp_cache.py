"""The NLPs of grasp structures, built once and kept: the cache a planner, a re-planner and a
controller share (issue 41; :class:`NlpCache`).

A grasp's NLP depends on its *structure* (:class:`GraspStructure`: the object's shape, the
palm, the grid's segments, the goal and via-point masks, the fingers, whether it tracks a
motion or a reference, plans forces, has the smooth timing or contact phases); everything
else is a parameter or a bound. :meth:`NlpCache.get` builds a structure's NLP with its
solver (:func:`~ocp.solve.ipopt.ipopt_solver`: IPOPT, or fatrop with the stage order;
compiled to C with ``compile_dir``, in a background thread with ``background``) or takes it
from the cache, the least recently used dropped beyond ``max_nlps``.
:meth:`NlpCache.structure_key` is the structure's public key: a string another process
computes alike for the same request (the fingers by their models, not by identity), what a
scheduler routes a job by to the worker whose cache holds its NLP.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import ValuesView
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ocp.solve.compiled import BackgroundCompiler
from ocp.solve.ipopt import NLP, ipopt_solver
from ocp.spec.chart_switch import after_switch, switch_node
from ocp.spec.grasp import ManipulationProblem
from ocp.spec.problem import Structure
from ocp.transcription.chart_switch import ChartSwitch
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.nlp_blocks import build_manipulation_nlp

__all__ = ["FORCE_REGULARISATION", "MAX_CACHED_NLPS", "GraspStructure", "NlpCache"]

#: Weight of the size of the internal-force variables (3+ contacts) in the objective.
FORCE_REGULARISATION = 1e-3

#: NLPs a cache keeps by default (:attr:`NlpCache.max_nlps`): a few MB each for one or two
#: fingers, ~40 MB for the four-finger hand's.
MAX_CACHED_NLPS = 24


@dataclass(frozen=True)
class GraspStructure:
    """What fixes the shape of a grasp's NLP (everything else is a parameter or a bound):
    the NLPs are cached by it. The fingers are compared by identity (the key keeps them
    alive); :meth:`fingerprint` names the same structure alike in another process."""

    #: the object surface's name (``ObjectSpec.surface.name``)
    shape: str
    palm: bool
    segments: tuple[int, ...]
    goal_mask: tuple[bool, ...]
    via_masks: tuple[tuple[bool, ...], ...]
    fingers: tuple[Any, ...]
    tracking: bool
    #: the contact forces are planned (``problem.forces``): more variables and rows
    forces: bool = False
    #: the smooth timing (``problem.timing``): one input per node, joint-acceleration rows
    smooth: bool = False
    #: the contact phases on the grid (``problem.schedule()``): None, one phase with every
    #: fingertip touching
    schedule: tuple[tuple[int, tuple[bool, ...]], ...] | None = None
    #: a reference trajectory tracked (``problem.reference``): its objective terms
    reference: bool = False
    #: the fingertips' contacts change chart (``problem.chart_switch``): the grid node and
    #: the next chart's surface name
    switch: tuple[int, str] | None = None

    @staticmethod
    def of(problem: ManipulationProblem) -> GraspStructure:
        segments, _ = problem.segments()
        goal_mask: tuple[bool, ...] = (False,) * 5
        via_masks: tuple[tuple[bool, ...], ...] = ()
        if problem.palm is not None:
            st = Structure.of(problem.palm_problem())
            goal_mask, via_masks = st.goal_mask, st.via_masks
        return GraspStructure(problem.object.surface.name, problem.palm is not None, segments,
                              goal_mask, via_masks, tuple(c.finger for c in problem.fingers),
                              problem.motion is not None, problem.forces is not None,
                              problem.smooth, problem.schedule(),
                              problem.reference is not None,
                              None if problem.chart_switch is None else
                              (switch_node(problem), after_switch(problem).object.surface.name))

    def fingerprint(self, m: GraspModel) -> str:
        """The structure as a string that another process computes alike: the fingers by
        their models (URDF, tip frame, mount, fingertip surface), not by identity."""
        import hashlib

        parts = [repr((self.shape, self.palm, self.segments, self.goal_mask, self.via_masks,
                       self.tracking, m.nx, m.nu)) + (":forces" if self.forces else "")
                 + (":smooth" if self.smooth else "")
                 + (f":phases={self.schedule!r}" if self.schedule is not None else "")
                 + (":reference" if self.reference else "")
                 + (f":switch={self.switch!r}" if self.switch is not None else "")]
        for f in self.fingers:
            parts += [hashlib.sha256(f.urdf_text.encode()).hexdigest(), f.tip_frame,
                      repr(np.asarray(f.base_rotation).round(12).tolist()),
                      repr(np.asarray(f.base_position).round(12).tolist()),
                      repr(f.tip_surface),  # the fingertip surface (issue 14)
                      repr(getattr(f, "couplings", ()))]  # its joints' couplings' rows
        return hashlib.sha256("|".join(parts).encode()).hexdigest()[:32]


class NlpCache:
    """The NLPs of grasp structures and the grasps' models (see the module)."""

    def __init__(self, compile_dir: Path | None = None, background: bool = False,
                 max_nlps: int = MAX_CACHED_NLPS, solver: str = "ipopt",
                 stage_order: bool | None = None) -> None:
        #: When set, each structure's NLP functions are generated as C, compiled with gcc
        #: and cached there (:func:`ocp.solve.compiled.compiled_block_solver`): seconds the
        #: first time, IPOPT about 40 % faster on experiment 1 (docs/performance.md).
        self.compile_dir = compile_dir
        #: The NLP solver (:data:`~ocp.solve.ipopt.SOLVERS`): "fatrop" solves the
        #: stage-ordered NLP with IPOPT as its fallback (issue 27; docs/performance.md).
        self.solver = solver
        #: Build the stage-ordered NLP (default: when the solver needs it).
        self.stage_order = solver == "fatrop" if stage_order is None else stage_order
        #: With ``background``, a new structure is solved in the virtual machine at once and
        #: compiled in a background thread (:class:`ocp.solve.compiled.BackgroundCompiler`);
        #: the compiled solver replaces it at the first solve after the compile (a service
        #: worker: no request waits for gcc). Without, the first solve compiles.
        self.compiler = BackgroundCompiler(compile_dir) if compile_dir is not None \
            and background else None
        #: The NLPs built, by structure, the least recently used dropped beyond this
        #: (every refined grid is a structure of its own).
        self.max_nlps = max_nlps
        self._entries: OrderedDict[GraspStructure, NLP] = OrderedDict()
        # keyed by the finger objects themselves (identity; the key keeps them alive)
        self._models: dict[tuple[Any, ...], GraspModel] = {}

    def __len__(self) -> int:
        return len(self._entries)

    def values(self) -> ValuesView[NLP]:
        return self._entries.values()

    def model(self, problem: ManipulationProblem) -> GraspModel:
        """The grasp's model (its CasADi functions), built once per (shape, palm,
        fingers)."""
        key = (problem.object.surface.name, problem.palm is not None,
               tuple(c.finger for c in problem.fingers))
        if key not in self._models:
            self._models[key] = GraspModel(*key)
        return self._models[key]

    def structure_key(self, problem: ManipulationProblem) -> str:
        """The public key of the problem's NLP: its structure's fingerprint (the same
        string in any process for the same structure and fingers' models), with the
        layout this cache builds."""
        return GraspStructure.of(problem).fingerprint(self.model(problem)) + \
            (":stages" if self.stage_order else "")

    def get(self, problem: ManipulationProblem) -> tuple[NLP, bool]:
        """The NLP of this problem's structure (:class:`GraspStructure`), built or from
        the cache, and whether it was cached."""
        key = GraspStructure.of(problem)
        if key in self._entries:
            self._entries.move_to_end(key)
            return self._entries[key], True
        m = self.model(problem)
        block = build_manipulation_nlp(m, key.segments, key.goal_mask, key.via_masks,
                                       key.tracking, FORCE_REGULARISATION,
                                       forces=key.forces, smooth=key.smooth,
                                       schedule=key.schedule, stage_order=self.stage_order,
                                       reference=key.reference,
                                       switch=None if key.switch is None else ChartSwitch(
                                           key.switch[0], self.model(after_switch(problem))))
        fingerprint = key.fingerprint(m) + (":stages" if self.stage_order else "")
        nlp = ipopt_solver(block, fingerprint, None if self.compiler else self.compile_dir,
                           self.solver)
        self._entries[key] = nlp
        while len(self._entries) > max(1, self.max_nlps):
            self._entries.popitem(last=False)
        if self.compiler is not None:
            self.compiler.submit(key, nlp.oracle, nlp.options, nlp.fingerprint)
        return nlp, False

    def adopt_compiled(self, wait: float = 0.0) -> int:
        """Swap in the compiled solvers of the background compiles that are done (waiting
        up to ``wait`` s for the pending ones); how many."""
        if self.compiler is None:
            return 0
        done = self.compiler.finished(wait)
        for key, solver, options in done:
            nlp = self._entries.get(key)
            if nlp is not None:
                nlp.solver, nlp.options, nlp.compiled = solver, options, True
                nlp.warm_solver = None  # rebuilt from the compiled options on first use
        return len(done)
