"""A gait's execution in MuJoCo (docs/gait.md, "Executed"): the simulator's plan of a
:class:`~ocp.gait.planner.GaitPlan`, every fingertip's contact with its planned activity
(lifted in its swing, its force ramped in the unloading and loading around it)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ocp import GaitPlan, GaitSamples, gait_samples, gait_times

from . import finger_spec, object_spec

__all__ = ["GAIT_FORCE_CONTROL", "GAIT_SQUEEZE", "gait_execution_plan",
           "samples_execution_plan"]

#: A gait's squeeze [m] (the simulator's default is 0.5 mm): a fifth, measured in
#: docs/gait.md "Executed" (the fingertips' unbalanced squeezes turn the ball while it
#: rolls; a gait rolls many times).
GAIT_SQUEEZE = 1e-4

#: A gait's force control (``sim.SimOptions.force_control``; 'off' for every other plan):
#: contact-force feedback on the planned forces as a shift of the servos' set points,
#: measured in docs/gait.md "Executed" (the servo alone delivers what the squeezes'
#: geometry makes, and a lightly loaded contact flickers off; feedback as torque cannot
#: bend the stiff servo far enough to close a 30 um gap).
GAIT_FORCE_CONTROL = "admittance"


def gait_execution_plan(gait: GaitPlan, problem: Any, rate: float = 200.0) -> Any:
    """The simulator's plan (a :class:`sim.ExecutionPlan`) of ``gait``, planned from the
    grasp ``problem`` (its fingers, object, friction and load), sampled at ``rate`` [Hz]
    and at every switch."""
    smp = gait_samples(gait, problem, gait_times(gait, rate))
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(problem.fingers))
    load = problem.forces
    return samples_execution_plan(smp, names, tuple(f.finger for f in problem.fingers),
                                  problem.object.shape,
                                  tuple(float(d) for d in problem.object.dimensions),
                                  float(load.mass), float(problem.mu), tuple(load.gravity))


def samples_execution_plan(smp: GaitSamples, names: tuple[str, ...], models: tuple[Any, ...],
                           shape: str, dimensions: tuple[float, ...], mass: float, mu: float,
                           gravity: tuple[float, ...], notes: tuple[str, ...] = ()) -> Any:
    """The simulator's plan of a gait's samples: the fingertips' planned forces fed
    forward (J^T f), the squeeze :data:`GAIT_SQUEEZE` and the force control
    :data:`GAIT_FORCE_CONTROL` unless the options give them; a lifted fingertip has no
    force, no squeeze, no grip and no force feedback (its contact's ``active``)."""
    from sim import ContactSpec, ExecutionPlan, FingerReference

    cut = np.cumsum((0, *(int(m.nq) for m in models)))
    specs = tuple(finger_spec(nm, m) for nm, m in zip(names, models, strict=True))
    refs = tuple(FingerReference(smp.q[:, cut[k]:cut[k + 1]], smp.q_dot[:, cut[k]:cut[k + 1]],
                                 None, smp.force[:, k]) for k in range(len(models)))
    contacts = tuple(ContactSpec(nm, "finger", nm, smp.point[:, k], smp.normal[:, k],
                                 smp.active[:, k]) for k, nm in enumerate(names))
    plan = ExecutionPlan(smp.t, object_spec(shape, dimensions, mass), smp.object_position,
                         smp.object_wxyz, specs, refs, contacts, None, mu, None,
                         (float(gravity[0]), float(gravity[1]), float(gravity[2])),
                         ("a gait: planned lift-offs and touch-downs (contacts' activity)",
                          *notes), squeeze=GAIT_SQUEEZE,
                         force_control=GAIT_FORCE_CONTROL)
    plan.check()
    return plan
