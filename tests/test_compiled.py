"""Compiled NLP solvers (ocp.solve.compiled): the same plans as CasADi's virtual machine, the
library compiled once per structure and found on disk by the next planner."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest
from helpers import assert_close

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.solution import Status
from ocp.solve.compiled import block_libraries
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="no gcc")


def small() -> BallOnPalmProblem:
    """A short roll on a coarse grid: a C file that compiles in a couple of seconds."""
    return BallOnPalmProblem(object=ObjectSpec("sphere", (0.03,)),
                             initial=(0.0, 0.0, 0.0, 0.0, 0.0),
                             goal={"x": 0.02, "y": 0.01, "psi": math.radians(10)},
                             duration=1.0, n_intervals=3, max_refinements=0)


def test_compiled_planner_gives_the_same_plan(tmp_path: Path) -> None:
    plain = BallOnPalmPlanner().solve(small())
    compiled = BallOnPalmPlanner(compile_dir=tmp_path).solve(small())
    assert plain.status is Status.SOLVED and compiled.status is Status.SOLVED
    assert compiled.certificate.passed
    assert_close(compiled.nodes.eta, plain.nodes.eta, atol=1e-9)
    # one structure: its NLP's functions and its derivative blocks, a library each
    assert len(list(tmp_path.glob("*.so"))) == 2
    again = BallOnPalmPlanner(compile_dir=tmp_path).solve(small())  # from the cache
    assert_close(again.nodes.eta, compiled.nodes.eta, atol=0)
    assert len(list(tmp_path.glob("*.so"))) == 2


def test_library_is_compiled_once_per_structure(tmp_path: Path) -> None:
    planner = BallOnPalmPlanner()
    nlp, _ = planner.nlp_for(small())
    _, hits = block_libraries(nlp.oracle, nlp.options, "small", tmp_path)
    assert hits == [False, False]  # the NLP's functions, its derivative blocks
    _, hits = block_libraries(nlp.oracle, nlp.options, "small", tmp_path)
    assert hits == [True, True] and len(list(tmp_path.glob("*.so"))) == 2
    _, hits = block_libraries(nlp.oracle, nlp.options, "another key", tmp_path)
    assert hits == [False, False] and len(list(tmp_path.glob("*.so"))) == 4


def test_a_missing_compiler_is_a_clear_error(tmp_path: Path) -> None:
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    with pytest.raises(RuntimeError, match="no C compiler"):
        block_libraries(nlp.oracle, nlp.options, "k", tmp_path, compiler="no-such-cc")


def test_processes_sharing_a_cache_compile_each_library_once(tmp_path: Path) -> None:
    """Two processes asking for the same library at once (a service's workers warming up
    the same structures): one compiles each library, the other waits on its lock and loads
    it (which process compiles which library is a race)."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    with ctx.Pool(2) as pool:
        hits = pool.starmap(_compile_small, [(str(tmp_path),)] * 2)
    for library in zip(*hits, strict=True):
        assert sorted(library) == [False, True]
    assert len(list(tmp_path.glob("*.so"))) == 2


def _compile_small(folder: str) -> list[bool]:
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    return block_libraries(nlp.oracle, nlp.options, "small", Path(folder))[1]
