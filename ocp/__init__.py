"""dexroll's planning core: dextrous manipulation with rolling contacts as direct
collocation (Han, Guan, Li, Shi, Trinkle).

What a library user needs is here::

    from ocp import BallOnPalmProblem, ObjectSpec, plan

    sol = plan(BallOnPalmProblem(object=ObjectSpec("sphere", (0.025,)),
                                 initial=(0, 0, 0, 0, 0), goal={"psi": 1.0}, duration=2.0))
    sol.status, sol.certificate.passed, sol.sample([0.5, 1.0]).eta

The data flow is in the folder names: ``certify`` (the certificate's types: checks with
name, value, tolerance and kind; a leaf), ``geometry`` (surfaces, Montana's contact
kinematics, rotations, grasp geometry) and ``robots`` (fingers from URDF through
Pinocchio, the built-in hands) -> ``spec`` (the object, the palm and fingertips, the
motion, the problems: data) -> ``contacts`` (each contact kind's CasADi model) ->
``transcription`` (collocation, the NLP's parameters, the grasp model, the NLP from
blocks) -> ``solution`` -> ``solve`` (IPOPT, initial guesses and strategies, the pipeline,
the certification of a plan). ``ball_on_palm`` and ``one_finger`` are front ends of the
pipeline for the paper's two settings; ``methods`` holds the paper's greedy method. The
names below are loaded on first use, so that ``import ocp.geometry.surfaces`` stays light.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ocp.ball_on_palm import BallOnPalmPlanner
    from ocp.certify.certificate import Certificate, Check, CheckKind, TolerancePolicy
    from ocp.contacts import FingertipContact, FreeFingertip, FreeObject, SupportContact
    from ocp.geometry.surfaces import SURFACES, Surface
    from ocp.methods.greedy import GreedyResult, greedy_plan
    from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem
    from ocp.robots.finger import FingerModel, load_finger
    from ocp.robots.hands import Hand, load_hand
    from ocp.solution import GraspSample, ManipulationSolution, Solution, Status, Trajectory
    from ocp.solve.planner import ManipulationPlanner
    from ocp.spec.grasp import Fingertip, ManipulationProblem, Palm, hand_fingertips
    from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose, Tracking
    from ocp.spec.problem import (
        BallOnPalmProblem,
        ObjectSpec,
        ProblemError,
        SolverOptions,
        ViaPoint,
    )

#: public name -> the module that defines it
_EXPORTS = {
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
    "ManipulationPlanner": "ocp.solve.planner",
    "FingertipContact": "ocp.contacts", "FreeFingertip": "ocp.contacts",
    "FreeObject": "ocp.contacts", "SupportContact": "ocp.contacts",
    "Fingertip": "ocp.spec.grasp", "ManipulationProblem": "ocp.spec.grasp",
    "Palm": "ocp.spec.grasp", "hand_fingertips": "ocp.spec.grasp",
    "DesiredMotion": "ocp.spec.motion", "MotionStep": "ocp.spec.motion",
    "ObjectPose": "ocp.spec.motion", "Tracking": "ocp.spec.motion",
    "BallOnPalmProblem": "ocp.spec.problem", "ObjectSpec": "ocp.spec.problem",
    "ProblemError": "ocp.spec.problem", "SolverOptions": "ocp.spec.problem",
    "ViaPoint": "ocp.spec.problem",
}

__all__ = [
    "SURFACES",
    "BallOnPalmPlanner",
    "BallOnPalmProblem",
    "Certificate",
    "Check",
    "CheckKind",
    "DesiredMotion",
    "FingerContact",
    "FingerModel",
    "Fingertip",
    "FingertipContact",
    "FreeFingertip",
    "FreeObject",
    "GraspSample",
    "GreedyResult",
    "Hand",
    "ManipulationPlanner",
    "ManipulationProblem",
    "ManipulationSolution",
    "MotionStep",
    "ObjectPose",
    "ObjectSpec",
    "OneFingerPlanner",
    "OneFingerProblem",
    "Palm",
    "ProblemError",
    "Solution",
    "SolverOptions",
    "Status",
    "SupportContact",
    "Surface",
    "TolerancePolicy",
    "Tracking",
    "Trajectory",
    "ViaPoint",
    "greedy_plan",
    "hand_fingertips",
    "load_finger",
    "load_hand",
    "plan",
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
    """Plan any problem with the process-wide planner of its kind (NLPs cached per
    structure): a :class:`BallOnPalmProblem` (-> :class:`Solution`), a
    :class:`OneFingerProblem` (-> its solution) or a :class:`ManipulationProblem` (->
    :class:`ManipulationSolution`); ``warm_start``: a previous plan of a similar problem.
    Raises :class:`ProblemError` (naming each bad field) before building anything."""
    from ocp import ball_on_palm
    from ocp.one_finger import OneFingerProblem
    from ocp.spec.grasp import ManipulationProblem
    from ocp.spec.problem import BallOnPalmProblem

    general = ball_on_palm.default_planner().general
    if isinstance(problem, BallOnPalmProblem):
        return ball_on_palm.default_planner().solve(problem, warm_start)
    if isinstance(problem, OneFingerProblem):
        from ocp.one_finger import OneFingerPlanner

        return OneFingerPlanner(general).solve(problem, warm_start)
    if isinstance(problem, ManipulationProblem):
        return general.solve(problem, warm_start)
    raise TypeError(f"no planner for {type(problem).__name__}; one of BallOnPalmProblem, "
                    "OneFingerProblem, ManipulationProblem")
