"""The transcription's contact phases: a grasp's motion as a sequence of phases, each with
its set of active contacts.

Today's grasps are one-phase schedules and must give the same NLP as before phases, row
for row: the signatures saved from the builder before them (tests/nlp_signature.py,
tests/data/nlp_signatures.npz) against the builder now."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import assert_close
from nlp_signature import CASES, build, signature

SAVED = np.load(Path(__file__).parent / "data" / "nlp_signatures.npz")


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_one_phase_grasp_gives_the_nlp_it_gave_before_phases(name: str) -> None:
    """Same sizes, bounds, sparsity patterns (the same rows and variables in the same
    order), and the same values at a random point to round-off."""
    now = signature(build(name)[1])
    for key in ("sizes", "lbg", "ubg", "jac_rows", "jac_cols", "hess_rows", "hess_cols"):
        np.testing.assert_array_equal(now[key], SAVED[f"{name}/{key}"], err_msg=key)
    for key in ("f", "g", "jac", "hess"):
        ref = SAVED[f"{name}/{key}"]
        assert np.all(np.isfinite(ref)), key
        assert_close(now[key], ref, atol=1e-10 * (1 + np.abs(ref)), err_msg=key)
