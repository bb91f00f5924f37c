"""dexroll's planning core: dextrous manipulation with rolling contacts as direct
collocation (Han, Guan, Li, Shi, Trinkle).

What a library user needs is here: one problem type (:class:`ManipulationProblem`, a
grasp: the object, an optional palm, fingertips, a horizon, what to achieve; the paper's
settings are presets of it, :mod:`ocp.presets`), one pipeline, one solution type
(:class:`ManipulationSolution`), and the one-NLP seam re-planning uses
(:func:`attempt`)::

    from ocp import ObjectSpec, plan, presets

    sol = plan(presets.ball_on_palm(ObjectSpec("sphere", (0.025,)),
                                    initial=(0, 0, 0, 0, 0), goal={"psi": 1.0}, duration=2.0))
    sol.status, sol.certificate.passed, sol.sample([0.5, 1.0]).x

The data flow is in the folder names: ``certify`` (the certificate's types: checks with
name, value, tolerance and kind; a leaf), ``geometry`` (surfaces, Montana's contact
kinematics, rotations, grasp geometry), ``shapes`` (the objects' shapes: each one's
surface, mass properties, MuJoCo geom) and ``robots`` (fingers from URDF through
Pinocchio, the built-in hands) -> ``spec`` (the object, the palm and fingertips, the
motion, the problems: data) -> ``contacts`` (each contact kind's CasADi model) ->
``transcription`` (collocation, the NLP's parameters, the grasp model, the NLP from
blocks) -> ``solution`` -> ``solve`` (IPOPT, initial guesses and strategies, the pipeline,
the certification of a plan). ``ball_on_palm`` and ``one_finger`` are front ends of the
pipeline for the paper's two settings (their plans in the paper's coordinates), ``presets``
builds those settings as the one problem type; ``methods`` holds the paper's greedy method. The
names below are loaded on first use, so that ``import ocp.geometry.surfaces`` stays light.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ocp.ball_on_palm import PALM_NX, BallOnPalmPlanner, certify_palm_plan, palm_model
    from ocp.certify.certificate import Certificate, Check, CheckKind, TolerancePolicy
    from ocp.contacts import FingertipContact, FreeFingertip, FreeObject, SupportContact
    from ocp.control import ControllerOptions, Tick, WindowController
    from ocp.gait.planner import GaitPhase, GaitPlan, plan_gait
    from ocp.gait.samples import GaitSamples, gait_samples, gait_times
    from ocp.gait.step import GaitStep, contact_of, replace_finger
    from ocp.geometry.rotations import quaternion_wxyz
    from ocp.geometry.surfaces import SURFACES, Surface
    from ocp.methods.greedy import GreedyResult, greedy_plan
    from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem
    from ocp.robots.finger import FingerModel, load_finger
    from ocp.robots.hands import HAND_NAMES, Hand, load_hand
    from ocp.shapes import SHAPES, Shape, shape_of
    from ocp.solution import (
        GraspSample,
        ManipulationSolution,
        PalmSolution,
        Solution,
        Status,
        Trajectory,
        status_from_ipopt,
    )
    from ocp.solve.attempt import AttemptOptions, attempt, shifted
    from ocp.solve.estimate import EstimateOptions, Measurement, StateEstimate, estimate_state
    from ocp.solve.guesses import (
        guess_loops,
        reference_input,
        rotation_symmetric,
        simulate_guess,
    )
    from ocp.solve.ipopt import IPOPT_OPTIONS
    from ocp.solve.planner import ManipulationPlanner
    from ocp.solve.replan import Replan, Replanner, ReplanOptions
    from ocp.spec.grasp import Fingertip, ManipulationProblem, Palm, hand_fingertips
    from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose, Tracking
    from ocp.spec.problem import (
        CONTACT_COORDS,
        PERIODIC,
        BallOnPalmProblem,
        ObjectSpec,
        ProblemError,
        SolverOptions,
        Structure,
        ViaPoint,
        goal_errors,
    )
    from ocp.spec.reference import Reference
    from ocp.transcription.collocation import left_input_columns, node_times

#: public name -> the module that defines it
_EXPORTS = {
    "GaitPhase": "ocp.gait.planner", "GaitPlan": "ocp.gait.planner",
    "plan_gait": "ocp.gait.planner", "GaitStep": "ocp.gait.step",
    "contact_of": "ocp.gait.step", "replace_finger": "ocp.gait.step",
    "GaitSamples": "ocp.gait.samples", "gait_samples": "ocp.gait.samples",
    "gait_times": "ocp.gait.samples",
    "BallOnPalmPlanner": "ocp.ball_on_palm",
    "Certificate": "ocp.certify.certificate", "Check": "ocp.certify.certificate",
    "CheckKind": "ocp.certify.certificate", "TolerancePolicy": "ocp.certify.certificate",
    "SURFACES": "ocp.geometry.surfaces", "Surface": "ocp.geometry.surfaces",
    "GreedyResult": "ocp.methods.greedy", "greedy_plan": "ocp.methods.greedy",
    "FingerContact": "ocp.one_finger", "OneFingerPlanner": "ocp.one_finger",
    "OneFingerProblem": "ocp.one_finger",
    "FingerModel": "ocp.robots.finger", "load_finger": "ocp.robots.finger",
    "Hand": "ocp.robots.hands", "load_hand": "ocp.robots.hands",
    "GraspSample": "ocp.solution", "ManipulationSolution": "ocp.solution",
    "Solution": "ocp.solution", "Status": "ocp.solution", "Trajectory": "ocp.solution",
    "PalmSolution": "ocp.solution",
    "ManipulationPlanner": "ocp.solve.planner",
    "AttemptOptions": "ocp.solve.attempt", "attempt": "ocp.solve.attempt",
    "shifted": "ocp.solve.attempt",
    # re-planning from a measured state (docs/replanning.md)
    "EstimateOptions": "ocp.solve.estimate", "Measurement": "ocp.solve.estimate",
    "StateEstimate": "ocp.solve.estimate", "estimate_state": "ocp.solve.estimate",
    "Replan": "ocp.solve.replan", "Replanner": "ocp.solve.replan",
    "ReplanOptions": "ocp.solve.replan",
    # tracking a plan at a controller's rate (docs/control.md)
    "ControllerOptions": "ocp.control", "Tick": "ocp.control",
    "WindowController": "ocp.control", "Reference": "ocp.spec.reference",
    "FingertipContact": "ocp.contacts", "FreeFingertip": "ocp.contacts",
    "FreeObject": "ocp.contacts", "SupportContact": "ocp.contacts",
    "Fingertip": "ocp.spec.grasp", "ManipulationProblem": "ocp.spec.grasp",
    "Palm": "ocp.spec.grasp", "hand_fingertips": "ocp.spec.grasp",
    "DesiredMotion": "ocp.spec.motion", "MotionStep": "ocp.spec.motion",
    "ObjectPose": "ocp.spec.motion", "Tracking": "ocp.spec.motion",
    "BallOnPalmProblem": "ocp.spec.problem", "ObjectSpec": "ocp.spec.problem",
    "ProblemError": "ocp.spec.problem", "SolverOptions": "ocp.spec.problem",
    "ViaPoint": "ocp.spec.problem",
    # the pieces of the ball-on-palm NLP a peer transcription re-uses (the benchmarks'
    # peers: planner_service/bench/peers.py)
    "PALM_NX": "ocp.ball_on_palm", "palm_model": "ocp.ball_on_palm",
    "certify_palm_plan": "ocp.ball_on_palm",
    "CONTACT_COORDS": "ocp.spec.problem", "PERIODIC": "ocp.spec.problem",
    "Structure": "ocp.spec.problem", "goal_errors": "ocp.spec.problem",
    "status_from_ipopt": "ocp.solution",
    "guess_loops": "ocp.solve.guesses", "reference_input": "ocp.solve.guesses",
    "rotation_symmetric": "ocp.solve.guesses", "simulate_guess": "ocp.solve.guesses",
    "IPOPT_OPTIONS": "ocp.solve.ipopt",
    "left_input_columns": "ocp.transcription.collocation",
    "node_times": "ocp.transcription.collocation",
    # what the plan viewer draws with (planner_service/view/)
    "HAND_NAMES": "ocp.robots.hands", "quaternion_wxyz": "ocp.geometry.rotations",
    # the objects' shapes (ocp/shapes/)
    "SHAPES": "ocp.shapes", "Shape": "ocp.shapes", "shape_of": "ocp.shapes",
}

__all__ = [
    "CONTACT_COORDS",
    "HAND_NAMES",
    "IPOPT_OPTIONS",
    "PALM_NX",
    "PERIODIC",
    "SHAPES",
    "SURFACES",
    "AttemptOptions",
    "BallOnPalmPlanner",
    "BallOnPalmProblem",
    "Certificate",
    "Check",
    "CheckKind",
    "ControllerOptions",
    "DesiredMotion",
    "EstimateOptions",
    "FingerContact",
    "FingerModel",
    "Fingertip",
    "FingertipContact",
    "FreeFingertip",
    "FreeObject",
    "GaitPhase",
    "GaitPlan",
    "GaitSamples",
    "GaitStep",
    "GraspSample",
    "GreedyResult",
    "Hand",
    "ManipulationPlanner",
    "ManipulationProblem",
    "ManipulationSolution",
    "Measurement",
    "MotionStep",
    "ObjectPose",
    "ObjectSpec",
    "OneFingerPlanner",
    "OneFingerProblem",
    "Palm",
    "PalmSolution",
    "ProblemError",
    "Reference",
    "Replan",
    "ReplanOptions",
    "Replanner",
    "Shape",
    "Solution",
    "SolverOptions",
    "StateEstimate",
    "Status",
    "Structure",
    "SupportContact",
    "Surface",
    "Tick",
    "TolerancePolicy",
    "Tracking",
    "Trajectory",
    "ViaPoint",
    "WindowController",
    "attempt",
    "certify_palm_plan",
    "contact_of",
    "estimate_state",
    "gait_samples",
    "gait_times",
    "goal_errors",
    "greedy_plan",
    "guess_loops",
    "hand_fingertips",
    "left_input_columns",
    "load_finger",
    "load_hand",
    "node_times",
    "palm_model",
    "plan",
    "plan_gait",
    "quaternion_wxyz",
    "reference_input",
    "replace_finger",
    "rotation_symmetric",
    "shape_of",
    "shifted",
    "simulate_guess",
    "status_from_ipopt",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'ocp' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__


def plan(problem: Any, warm_start: Any = None) -> Any:
    """Plan a :class:`ManipulationProblem` (the one problem type; :mod:`ocp.presets` builds
    the paper's settings as one) with the process-wide planner (NLPs cached per
    structure): a :class:`ManipulationSolution`. ``warm_start``: a previous plan of a
    similar problem. Raises :class:`ProblemError` (naming each bad field) before building
    anything.

    The paper's front-end problems are planned by their front ends and presented in their
    coordinates: a :class:`BallOnPalmProblem` gives a :class:`PalmSolution`, a
    :class:`OneFingerProblem` a one-finger solution (each carries the general plan)."""
    from ocp import ball_on_palm
    from ocp.one_finger import OneFingerProblem
    from ocp.solve.planner import default_planner
    from ocp.spec.grasp import ManipulationProblem
    from ocp.spec.problem import BallOnPalmProblem

    if isinstance(problem, ManipulationProblem):
        return default_planner().solve(problem, warm_start)
    if isinstance(problem, BallOnPalmProblem):
        return ball_on_palm.default_planner().solve(problem, warm_start)
    if isinstance(problem, OneFingerProblem):
        from ocp.one_finger import OneFingerPlanner

        return OneFingerPlanner(default_planner()).solve(problem, warm_start)
    raise TypeError(f"no planner for {type(problem).__name__}; a ManipulationProblem "
                    "(ocp.presets builds the paper's settings), BallOnPalmProblem or "
                    "OneFingerProblem")
