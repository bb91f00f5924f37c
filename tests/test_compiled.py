"""Compiled NLP solvers (ocp.compiled): the same plans as CasADi's virtual machine, the
library compiled once per structure and found on disk by the next planner."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest
from helpers import assert_close

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.compiled import compiled_solver
from ocp.problem import BallOnPalmProblem, ObjectSpec
from ocp.solution import Status

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
    assert len(list(tmp_path.glob("*.so"))) == 1


def test_library_is_compiled_once_per_structure(tmp_path: Path) -> None:
    planner = BallOnPalmPlanner()
    nlp, _ = planner.nlp_for(small())
    opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False}
    _, hit = compiled_solver(nlp.solver, "small", opts, tmp_path)
    assert not hit
    _, hit = compiled_solver(nlp.solver, "small", opts, tmp_path)
    assert hit and len(list(tmp_path.glob("*.so"))) == 1
    _, hit = compiled_solver(nlp.solver, "another key", opts, tmp_path)
    assert not hit and len(list(tmp_path.glob("*.so"))) == 2


def test_a_missing_compiler_is_a_clear_error(tmp_path: Path) -> None:
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    with pytest.raises(RuntimeError, match="no C compiler"):
        compiled_solver(nlp.solver, "k", {}, tmp_path, compiler="no-such-cc")


def test_processes_sharing_a_cache_compile_each_library_once(tmp_path: Path) -> None:
    """Two processes asking for the same library at once (a service's workers warming up
    the same structures): one compiles it, the other waits on the lock and loads it."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    with ctx.Pool(2) as pool:
        hits = pool.starmap(_compile_small, [(str(tmp_path),)] * 2)
    assert sorted(hits) == [False, True]
    assert len(list(tmp_path.glob("*.so"))) == 1


def _compile_small(folder: str) -> bool:
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False}
    return compiled_solver(nlp.solver, "small", opts, Path(folder))[1]
