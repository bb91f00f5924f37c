"""Compiled NLP solvers (ocp.solve.compiled): the same plans as CasADi's virtual machine, the
library compiled once per structure and found on disk by the next planner."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest
from helpers import assert_close

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.solution import Solution, Status
from ocp.solve.compiled import block_libraries
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="no gcc")


def small() -> BallOnPalmProblem:
    """A short roll on a coarse grid: a C file that compiles in a couple of seconds (the
    paper's timing: 3 intervals cannot resolve a smooth plan's ramps)."""
    return BallOnPalmProblem(object=ObjectSpec("sphere", (0.03,)),
                             initial=(0.0, 0.0, 0.0, 0.0, 0.0),
                             goal={"x": 0.02, "y": 0.01, "psi": math.radians(10)},
                             duration=1.0, n_intervals=3, max_refinements=0, timing="paper")


@pytest.fixture(scope="module")
def compiled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Solution]:
    """``small()`` planned with a fresh cache folder: its structure's libraries compiled
    (seconds of gcc each; once for the module), and the plan."""
    folder = tmp_path_factory.mktemp("compiled")
    return folder, BallOnPalmPlanner(compile_dir=folder).solve(small())


def test_compiled_planner_gives_the_same_plan(compiled: tuple[Path, Solution]) -> None:
    folder, plan = compiled
    plain = BallOnPalmPlanner().solve(small())
    assert plain.status is Status.SOLVED and plan.status is Status.SOLVED
    assert plan.certificate.passed
    assert_close(plan.nodes.eta, plain.nodes.eta, atol=1e-9)
    # one structure: its NLP's functions and its derivative blocks, a library each
    libraries = sorted(folder.glob("*.so"))
    assert len(libraries) == 2
    stamps = [p.stat().st_mtime_ns for p in libraries]
    again = BallOnPalmPlanner(compile_dir=folder).solve(small())  # from the cache
    assert_close(again.nodes.eta, plan.nodes.eta, atol=0)
    assert sorted(folder.glob("*.so")) == libraries
    assert [p.stat().st_mtime_ns for p in libraries] == stamps  # loaded, not compiled again


def test_library_is_compiled_once_per_structure(compiled: tuple[Path, Solution],
                                                tmp_path: Path) -> None:
    """The planner's libraries (a copy of its folder) are found under its structure's key
    by the next caller (another key compiles libraries of its own:
    test_processes_sharing_a_cache_compile_each_library_once, in a copy of the same
    folder)."""
    shared = tmp_path / "shared"
    shutil.copytree(compiled[0], shared)
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    _, hits = block_libraries(nlp.oracle, nlp.options, nlp.fingerprint, shared)
    assert hits == [True, True] and len(list(shared.glob("*.so"))) == 2


def test_a_missing_compiler_is_a_clear_error(tmp_path: Path) -> None:
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    with pytest.raises(RuntimeError, match="no C compiler"):
        block_libraries(nlp.oracle, nlp.options, "k", tmp_path, compiler="no-such-cc")


def test_processes_sharing_a_cache_compile_each_library_once(compiled: tuple[Path, Solution],
                                                            tmp_path: Path) -> None:
    """Two processes asking for the same library at once (a service's workers warming up
    the same structures): one compiles each library, the other waits on its lock and loads
    it (which process compiles which library is a race). In a copy of the planner's folder:
    the key "small" is not its structure's, so its libraries are compiled beside the
    planner's (the NLP's functions, its derivative blocks: one library each per key)."""
    import multiprocessing as mp

    shared = tmp_path / "shared"
    shutil.copytree(compiled[0], shared)
    ctx = mp.get_context("spawn")
    with ctx.Pool(2) as pool:
        hits = pool.starmap(_compile_small, [(str(shared),)] * 2)
    for library in zip(*hits, strict=True):
        assert sorted(library) == [False, True]
    assert len(list(shared.glob("*.so"))) == 4


def _compile_small(folder: str) -> list[bool]:
    nlp, _ = BallOnPalmPlanner().nlp_for(small())
    return block_libraries(nlp.oracle, nlp.options, "small", Path(folder))[1]
