"""The block-assembled derivatives of the manipulation NLP (ocp.transcription.nlp_blocks)
are the NLP's own: its constraint Jacobian and the Hessian of its Lagrangian equal
CasADi's derivatives of the same (f, g) at random points, for every kind of grasp (a palm
with via-points and a finger; two fingers tracking a motion; three fingers with internal
forces), and the compiled NLP gives the same plan as the virtual machine's."""

from __future__ import annotations

import math
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from test_manipulation import OBJ, one_finger_roll, two_fingers

from ocp.one_finger import OneFingerPlanner
from ocp.robots.hands import load_hand
from ocp.solution import Status
from ocp.solve.planner import (
    DesiredMotion,
    ManipulationPlanner,
    ManipulationProblem,
    MotionStep,
    ObjectPose,
    Tracking,
    hand_fingertips,
)
from ocp.spec.problem import ViaPoint


def palm_with_via_points() -> ManipulationProblem:
    problem = OneFingerPlanner.manipulation_problem(one_finger_roll())
    assert problem.palm is not None
    palm = replace(problem.palm, goal={"x": 0.0, "y": 0.0},
                   via_points=(ViaPoint(0.7, {"x": 0.008}), ViaPoint(1.4, {"y": 0.006})))
    return replace(problem, palm=palm, n_intervals=6)


def three_fingers() -> ManipulationProblem:
    hand = load_hand("three_finger")
    start = ObjectPose(position=hand.nominal_object_position)
    return ManipulationProblem(
        OBJ, hand_fingertips(hand, start, OBJ), 2.0, initial_pose=start,
        motion=DesiredMotion.from_steps(start, [MotionStep(2.0, (1.0, 0.0, 1.0),
                                                           math.radians(20.0))]),
        tracking=Tracking(position_tolerance=1e-3, orientation_tolerance=math.radians(1.0)),
        n_intervals=4)


CASES = {"palm_via_points": palm_with_via_points, "two_fingers_tracking":
         lambda: two_fingers(n=4), "three_fingers_forces": three_fingers}


@pytest.mark.parametrize("name", sorted(CASES))
def test_block_jacobian_and_hessian_are_the_nlps_own(name: str) -> None:
    problem = CASES[name]()
    planner = ManipulationPlanner()
    nlp, _ = planner.build(problem)
    p = planner.parameters(problem, nlp)
    nw, ng = nlp.pack.nnz_out(0), len(nlp.lbg)
    w, lam_g = ca.MX.sym("w", nw), ca.MX.sym("lam_g", ng)
    lam_f = ca.MX.sym("lam_f")
    f, g = nlp.oracle(w, p)
    reference = ca.Function("reference", [w, lam_f, lam_g],
                            [ca.jacobian(g, w), ca.triu(ca.hessian(lam_f * f
                                                                   + ca.dot(lam_g, g), w)[0])])
    x0 = planner.initial_state(problem)
    rng = np.random.default_rng(7)
    m = planner.model(problem)
    scale = np.asarray(m.x_scale(problem.object.length_scale), dtype=float)
    n_x, n_xm = nlp.hs.X.numel(), nlp.hs.Xm.numel()
    for _ in range(2):
        w0 = 0.1 * rng.normal(size=nw)
        # states near the initial grasp (the contact charts stay away from their poles)
        for start, count in ((0, problem.n_intervals + 1), (n_x, problem.n_intervals)):
            X = np.tile(x0, (count, 1)) + 0.05 * rng.normal(size=(count, len(x0)))
            w0[start:start + count * len(x0)] = (X / scale).ravel()
        assert n_x + n_xm <= nw
        lf, lg = 1.3, rng.normal(size=ng)
        J_ref, H_ref = (np.asarray(ca.DM(a).full()) for a in reference(w0, lf, lg))
        _, J = nlp.options["jac_g"](w0, p)
        H = nlp.options["hess_lag"](w0, p, lf, lg)
        J, H = np.asarray(ca.DM(J).full()), np.asarray(ca.DM(H).full())
        assert np.all(np.isfinite(J_ref)) and np.all(np.isfinite(H_ref))
        assert_close(J, J_ref, atol=1e-9 * max(1.0, float(np.abs(J_ref).max())))
        assert_close(H, H_ref, atol=1e-9 * max(1.0, float(np.abs(H_ref).max())))
        # and the constraint values that come with the Jacobian are g itself
        g_ref = np.asarray(nlp.oracle(w0, p)[1]).ravel()
        assert_close(np.asarray(nlp.options["jac_g"](w0, p)[0]).ravel(), g_ref, atol=0.0)


@pytest.mark.slow  # (gcc, 10-15 s: the service's opt-in DEXROLL_COMPILE_DIR)
@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_the_compiled_nlp_plans_what_the_virtual_machine_plans(tmp_path: Path) -> None:
    # not refined: the certificate of the returned trajectory asks for 192 intervals,
    # whose compile takes minutes on this machine; the two plans are compared as they are
    problem = replace(palm_with_via_points(), n_intervals=12, max_refinements=0)
    # the plan's deadline counts the compile (gcc, a minute on a loaded machine)
    problem = replace(problem, options=replace(problem.options, time_limit=900.0))
    plain: Any = ManipulationPlanner().solve(problem)
    compiled_planner = ManipulationPlanner(compile_dir=tmp_path)
    compiled = compiled_planner.solve(problem)
    nlp, _ = compiled_planner.build(problem)
    assert nlp.compiled
    assert plain.raw_status == compiled.raw_status == "Solve_Succeeded"
    assert plain.status is compiled.status
    assert_close(compiled.X, plain.X, atol=1e-8)
    assert [c.name for c in compiled.certificate.checks if not c.passed] == \
        [c.name for c in plain.certificate.checks if not c.passed]
    # two libraries per structure (problem functions, block derivatives; a refined grid
    # is another structure, and so is the palm alone whose plan seeds the guess) are
    # cached on disk, and a second planner (another process, say) loads them instead of
    # compiling again
    libraries = sorted(p for p in tmp_path.iterdir() if p.is_file())
    assert {p.suffix for p in libraries} == {".so"}
    structures = 1 + compiled.refinements + 1
    assert len(compiled_planner.nlps) == structures
    assert len(libraries) == 2 * structures
    stamps = [p.stat().st_mtime_ns for p in libraries]
    again = ManipulationPlanner(compile_dir=tmp_path)
    again.prepare(problem)
    assert again.build(problem)[0].compiled
    assert sorted(p for p in tmp_path.iterdir() if p.is_file()) == libraries
    assert [p.stat().st_mtime_ns for p in libraries] == stamps


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_a_background_compile_takes_over_between_solves(tmp_path: Path) -> None:
    """With ``background``, the first plan is solved in the virtual machine at once while
    gcc runs in a thread; once the compile is done the next solve runs the compiled NLP and
    plans the same; the libraries are cached like a foreground compile's. The object on
    the palm alone (one structure, its small SX form: seconds of gcc; the finger's
    structure compiles in the test above)."""
    from ocp.ball_on_palm import grasp_problem
    from ocp.spec.problem import BallOnPalmProblem, ObjectSpec

    problem = grasp_problem(BallOnPalmProblem(
        object=ObjectSpec("sphere", (0.03,)), initial=(0.0, 0.0, 0.0, 0.0, 0.0),
        goal={"x": 0.02, "y": 0.01}, duration=1.0, n_intervals=6, max_refinements=0,
        timing="paper"))
    planner = ManipulationPlanner(compile_dir=tmp_path, background=True)
    first: Any = planner.solve(problem)
    nlp, _ = planner.build(problem)
    assert planner.compiler is not None and not planner.compiler.errors
    assert first.raw_status == "Solve_Succeeded" and first.refinements == 0
    structures = 1
    assert len(planner.nlps) == structures
    assert not nlp.compiled  # swapped in only between solves
    assert planner.adopt_compiled(wait=300.0) == structures
    assert nlp.compiled and planner.compiler.pending == 0 and not planner.compiler.errors
    second: Any = planner.solve(problem)
    assert second.raw_status == "Solve_Succeeded" and second.status is first.status
    assert second.refinements == first.refinements
    assert_close(second.X, first.X, atol=1e-8)
    # no temporary folder left: the libraries and the folder of their compile locks
    assert {p.name for p in tmp_path.iterdir() if p.is_dir()} == {".locks"}
    libraries = [p for p in tmp_path.iterdir() if p.is_file()]
    assert {p.suffix for p in libraries} == {".so"} and len(libraries) == 2 * structures
    # a foreground planner finds the same libraries in the cache
    again = ManipulationPlanner(compile_dir=tmp_path)
    again.prepare(problem)
    assert again.build(problem)[0].compiled
    assert sorted(p for p in tmp_path.iterdir() if p.is_file()) == sorted(libraries)


def test_a_background_compile_without_a_compiler_keeps_the_virtual_machine(
        tmp_path: Path) -> None:
    problem = palm_with_via_points()
    planner = ManipulationPlanner(compile_dir=tmp_path, background=True)
    assert planner.compiler is not None
    planner.compiler.compiler = "no-such-cc"
    sol: Any = planner.solve(problem)
    assert sol.status is Status.SOLVED and not planner.build(problem)[0].compiled
    assert planner.compiler.pending == 0
    assert any("no C compiler" in e for e in planner.compiler.errors)


def test_the_small_sx_form_is_the_block_nlp() -> None:
    """The object on the palm alone is written out in SX (cheaper at this size): the same
    objective, constraints and derivatives as the blocks' at random points, with via-points
    (the input jumps there)."""
    from ocp.ball_on_palm import grasp_problem
    from ocp.solve.nlp_cache import FORCE_REGULARISATION, GraspStructure
    from ocp.spec.problem import BallOnPalmProblem, ObjectSpec
    from ocp.transcription.nlp_blocks import build_manipulation_nlp

    problem = grasp_problem(BallOnPalmProblem(
        object=ObjectSpec("ellipsoid", (0.025, 0.035)), initial=(0.0, 0.0, 0.1, 0.2, 0.3),
        goal={"x": 0.01, "psi": 0.4}, duration=2.0, n_intervals=8,
        via_points=(ViaPoint(0.7, {"y": 0.01, "v": 0.1}),)))
    m = ManipulationPlanner().model(problem)
    key = GraspStructure.of(problem)
    args = (m, key.segments, key.goal_mask, key.via_masks, key.tracking, FORCE_REGULARISATION)
    small = build_manipulation_nlp(*args)
    blocks = build_manipulation_nlp(*args, small=False)
    assert small.params == blocks.params and small.pack.nnz_out(0) == blocks.pack.nnz_out(0)
    assert_close(small.lbg, blocks.lbg, atol=0) and len(small.ubg) == len(blocks.ubg)
    rng = np.random.default_rng(5)
    p = ManipulationPlanner.parameters(problem, small)
    for _ in range(3):
        w = 0.2 * rng.normal(size=small.pack.nnz_out(0))
        lam = rng.normal(size=len(small.lbg))
        for a, b in zip(small.oracle(w, p), blocks.oracle(w, p), strict=True):
            assert_close(np.asarray(a), np.asarray(b), atol=1e-12, rtol=1e-12)
        assert_close(np.asarray(small.jac_g(w, p)[1]), np.asarray(blocks.jac_g(w, p)[1]),
                     atol=1e-12, rtol=1e-12)
        assert_close(np.asarray(small.hess_lag(w, p, 0.7, lam)),
                     np.asarray(blocks.hess_lag(w, p, 0.7, lam)), atol=1e-10, rtol=1e-10)
    with pytest.raises(ValueError, match="without path rows"):
        build_manipulation_nlp(*args[:4], True, FORCE_REGULARISATION, small=True)
