"""Executing a plan in MuJoCo (docs/simulation.md).

The planner states a motion; this package checks, in a physics engine nobody here wrote,
that a hand following it actually moves the object so. It is independent of the planner
(``ocp``) and of the service: it takes an :class:`ExecutionPlan` (the plan's models and
motion as plain data; ``planner_service.execution`` builds one from a result and its
request), builds an MJCF scene (:mod:`.scene`), runs a controller (:class:`SimOptions`)
and reports the object's tracking errors, contact losses, slip and forces
(:class:`SimReport`).

* :mod:`.spec`: the plan as data; :mod:`.options`: contact model, controller, grip,
  tolerances; :mod:`.scene`: the MJCF; :mod:`.run`: the simulation; :mod:`.report`: the
  report and its figure.
"""

from __future__ import annotations

from .options import MODES, SimOptions, Tolerances
from .report import ContactReport, ErrorSummary, SimReport, plot
from .run import Simulation, simulate
from .scene import mjcf
from .spec import (
    DEFAULT_MASS,
    ContactSpec,
    ExecutionPlan,
    FingerReference,
    FingerSpec,
    JointSpec,
    ObjectSpec,
    TipShape,
)

__all__ = [
    "DEFAULT_MASS",
    "MODES",
    "ContactReport",
    "ContactSpec",
    "ErrorSummary",
    "ExecutionPlan",
    "FingerReference",
    "FingerSpec",
    "JointSpec",
    "ObjectSpec",
    "SimOptions",
    "SimReport",
    "Simulation",
    "TipShape",
    "Tolerances",
    "mjcf",
    "plot",
    "simulate",
]
