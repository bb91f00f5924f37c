"""The paper's settings as presets of the one problem type.

Every plan is a :class:`~ocp.spec.grasp.ManipulationProblem` (a grasp: the object, an
optional palm, fingertips, a horizon, what to achieve) solved by one pipeline into a
:class:`~ocp.solution.ManipulationSolution`. The paper's two settings are presets that
build one, with the argument names of the paper's own problems (each checked by its rules
first, so that an error names the field as given)::

    from ocp import plan, presets
    from ocp.spec.problem import ObjectSpec

    problem = presets.ball_on_palm(ObjectSpec("sphere", (0.025,)),
                                   initial=(0, 0, 0, 0, 0), goal={"psi": 1.0}, duration=2.0)
    sol = plan(problem)            # a ManipulationSolution, like every plan
    sol.status, sol.certificate.passed, sol.sample([0.5, 1.0]).x

* :func:`ball_on_palm`: the object rolled on the palm alone (section 2 of the paper);
* :func:`one_finger`: a finger pressing it on the palm (section 3, experiment 1);
* a grasp in the air (section 4, experiment 2) or any hand: build the problem itself, e.g.
  with :func:`~ocp.spec.grasp.hand_fingertips`.

The special front ends (:class:`~ocp.ball_on_palm.BallOnPalmPlanner`,
:class:`~ocp.one_finger.OneFingerPlanner`) plan the same problems and present the plan in
the paper's coordinates (the palm contact's eta, the finger's); the wire's
``ball_on_palm`` and ``one_finger`` results are those.
"""

from __future__ import annotations

from typing import Any

from ocp.ball_on_palm import grasp_problem
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem
from ocp.spec.grasp import ManipulationProblem
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ProblemError, ViaPoint

__all__ = ["ball_on_palm", "one_finger"]


def ball_on_palm(object: ObjectSpec, initial: tuple[float, float, float, float, float],
                 goal: dict[str, float],
                 duration: float, via_points: tuple[ViaPoint, ...] = (), **options: Any
                 ) -> ManipulationProblem:
    """The object on the palm alone, rolled from the palm contact coordinates ``initial``
    (x, y, u, v, psi) to ``goal`` (any of them, by name) through ``via_points`` in
    ``duration`` seconds; ``options``: any other field of
    :class:`~ocp.spec.problem.BallOnPalmProblem` (``n_intervals``, ``timing``, ...).
    :class:`~ocp.spec.problem.ProblemError` names each bad field."""
    base = BallOnPalmProblem(object=object, initial=initial, goal=goal, duration=duration,
                             via_points=via_points, **options)
    base.validate()
    return grasp_problem(base)


def one_finger(base: BallOnPalmProblem, contact: FingerContact, finger: Any = None,
               mu: float = 0.5, **options: Any) -> ManipulationProblem:
    """A finger pressing the object on the palm (the paper's section 3): the palm's
    problem ``base`` (its initial contact, goal, via-points, duration, grid), the finger
    contact's initial coordinates and chart (``contact``), the finger (a
    :class:`~ocp.robots.finger.FingerModel`; None: the built-in one), the friction
    coefficient; ``options``: any other field of :class:`~ocp.one_finger.OneFingerProblem`.
    The fingertip is named ``finger`` in the plan."""
    from ocp.robots.finger import load_finger

    problem = OneFingerProblem(base=base, finger=finger if finger is not None
                               else load_finger(), contact=contact, mu=mu, **options)
    errs = problem.errors()
    if errs:
        raise ProblemError(errs)
    return OneFingerPlanner.manipulation_problem(problem)
