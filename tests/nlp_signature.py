"""The NLP of a few grasp structures as numbers (tests/test_transcription_phases.py):
every constraint bound, the sparsity of the constraint Jacobian and of the Lagrangian's
Hessian, and the objective, constraints and their derivatives at one random point. Saved
from the builder before contact phases (tests/data/nlp_signatures.npz), so that the
phased transcription is checked to give today's grasps the same NLP, row for row."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ocp.robots.finger import load_finger
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.nlp_blocks import build_manipulation_nlp

FORCE_REGULARISATION = 1e-3


def _fingers(k: int) -> tuple[Any, ...]:
    """k copies of the built-in finger turned about the palm's z axis (their geometry does
    not matter to the NLP's algebra, only their joints)."""
    out = []
    for i in range(k):
        a = 2 * math.pi * i / k
        c, s = math.cos(a), math.sin(a)
        out.append(load_finger(base_rotation=[[c, -s, 0], [s, c, 0], [0, 0, 1]]))
    return tuple(out)


#: name -> (shape, palm, number of fingers, segments, goal mask, via masks, tracking,
#: forces, smooth)
CASES: dict[str, tuple[Any, ...]] = {
    "palm_alone": ("sphere", True, 0, (2, 2), (True,) * 5, ((True, True, False, False,
                                                             False),), False, False, True),
    "palm_finger_paper": ("sphere", True, 1, (2, 2), (True, True, False, False, False),
                          ((True, True, False, False, False),), False, False, False),
    "palm_finger_smooth": ("sphere", True, 1, (3,), (True, True, False, False, False), (),
                           False, False, True),
    "two_fingers": ("sphere", False, 2, (3,), (False,) * 5, (), True, False, True),
    "three_fingers_forces": ("sphere", False, 3, (3,), (False,) * 5, (), True, True, True),
    "ellipsoid_palm_finger_forces": ("ellipsoid", True, 1, (3,), (True,) * 5, (), False,
                                     True, False),
}


def build(name: str, builder: Any = build_manipulation_nlp) -> Any:
    shape, palm, k, segments, goal_mask, via_masks, tracking, forces, smooth = CASES[name]
    m = GraspModel(shape, palm, _fingers(k))
    return m, builder(m, segments, goal_mask, via_masks, tracking, FORCE_REGULARISATION,
                      forces=forces, smooth=smooth)


def signature(block: Any, seed: int = 7) -> dict[str, np.ndarray]:
    """The NLP's bounds, sparsity patterns and values at one random point."""
    rng = np.random.default_rng(seed)
    nw, ng, npar = block.pack.nnz_out(0), len(block.lbg), block.params.size
    w = 0.3 * rng.standard_normal(nw)
    p = 0.5 + 0.2 * rng.random(npar)
    lam = rng.standard_normal(ng)
    f, g = (np.asarray(v, dtype=float).ravel() for v in block.oracle(w, p))
    _, J = block.jac_g(w, p)
    H = block.hess_lag(w, p, 0.7, lam)
    jr, jc = J.sparsity().get_triplet()
    hr, hc = H.sparsity().get_triplet()
    return {"lbg": np.asarray(block.lbg), "ubg": np.asarray(block.ubg),
            "jac_rows": np.asarray(jr), "jac_cols": np.asarray(jc),
            "hess_rows": np.asarray(hr), "hess_cols": np.asarray(hc),
            "f": f, "g": g, "jac": np.asarray(J.nonzeros()), "hess": np.asarray(H.nonzeros()),
            "sizes": np.array([nw, ng, npar])}


if __name__ == "__main__":  # regenerate the saved signatures (only with a reviewed reason)
    from pathlib import Path

    out = {f"{name}/{k}": v for name in CASES for k, v in signature(build(name)[1]).items()}
    np.savez_compressed(Path(__file__).parent / "data" / "nlp_signatures.npz", **out)
    print({name: out[f"{name}/sizes"].tolist() for name in CASES})
