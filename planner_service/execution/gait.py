"""A gait's execution in MuJoCo (docs/gait.md, "Executed"): the simulator's plan of a
:class:`~ocp.gait.planner.GaitPlan`, every fingertip's contact with its planned activity
(lifted in its swing, its force ramped in the unloading and loading around it)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ocp import GaitPlan, contact_of, quaternion_wxyz

from . import finger_spec

__all__ = ["TRANSITION", "gait_execution_plan"]

#: A contact's activity in a swing's lift-off and approach (``sim.ContactSpec.active``):
#: planned to leave or reach the object there, neither touching nor lifted.
TRANSITION = 0.25


def _times(gait: GaitPlan, rate: float) -> np.ndarray:
    t = np.linspace(0.0, gait.duration, max(2, int(np.ceil(gait.duration * rate)) + 1))
    edges = [p.start for p in gait.phases] + [gait.duration]
    return np.unique(np.concatenate([t, edges]))


def gait_execution_plan(gait: GaitPlan, problem: Any, rate: float = 200.0) -> Any:
    """The simulator's plan (a :class:`sim.ExecutionPlan`) of ``gait``, planned from the
    grasp ``problem`` (its fingers, object, friction and load), sampled at ``rate`` [Hz]
    and at every switch. The fingertips' planned forces are fed forward (J^T f); a
    lifted fingertip has no force, no squeeze and no grip."""
    from sim import ContactSpec, ExecutionPlan, FingerReference, ObjectSpec

    if not gait.phases:
        raise ValueError("the gait has no phases: nothing to execute")
    fingers = tuple(f.finger for f in problem.fingers)
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(problem.fingers))
    nf = len(fingers)
    cut = np.cumsum((0, *gait.nq))
    rho = float(problem.object.dimensions[0])
    ts = _times(gait, rate)
    n = ts.size
    Q, QD = np.zeros((n, int(cut[-1]))), np.zeros((n, int(cut[-1])))
    pos, wxyz = np.zeros((n, 3)), np.zeros((n, 4))
    force = np.zeros((n, nf, 3))
    active = np.ones((n, nf))
    pose = problem.initial_pose
    last = (np.asarray(pose.position, dtype=float), pose.rotation)
    ends = {}  # the object's pose at each roll's end
    for ph in gait.phases:
        if ph.kind == "roll":
            sol = gait.rolls[ph.index]
            ends[ph.index] = (sol.object_position[-1], sol.object_rotation[-1])
    phase_of = np.array([next((j for j, p in enumerate(gait.phases) if t <= p.end + 1e-12),
                              len(gait.phases) - 1) for t in ts])
    for j, ph in enumerate(gait.phases):
        rows = np.flatnonzero(phase_of == j)
        if not rows.size:
            if ph.kind == "roll":
                last = ends[ph.index]
            continue
        tl = ts[rows] - ph.start
        if ph.kind == "roll":  # the roll's own polynomials, every time at once
            sol = gait.rolls[ph.index]
            jt = sol.joint_trajectory(tl)
            Q[rows], QD[rows] = jt.positions, jt.velocities
            smp = sol.sample(tl)
            pos[rows], wxyz[rows] = smp.object_position, quaternion_wxyz(smp.object_rotation)
            force[rows] = sol.forces(tl)[0]
            last = ends[ph.index]
            continue
        for r, t in zip(rows, ts[rows], strict=True):
            Q[r], QD[r], _ = gait.joints(float(t))
        pos[rows], wxyz[rows] = last[0], quaternion_wxyz(last[1])
        step = gait.steps[ph.index]
        k = step.finger
        s = np.clip(tl / max(ph.end - ph.start, 1e-12), 0.0, 1.0)
        if ph.kind == "swing":
            force[rows] = np.insert(step.forces[1], k, 0.0, axis=0)
            assert step.swing is not None
            # lifted where the plan keeps it clear; in the lift-off and the approach
            # (touching at their ends) neither a loss nor a touch counts
            active[rows, k] = [0.0 if step.swing.segment(float(x)) == "clear"
                               else TRANSITION for x in tl]
        else:
            force[rows] = np.array([step.ramp_forces(ph.kind, float(x)) for x in s])
            active[rows, k] = np.maximum(1.0 - s if ph.kind == "unload" else s, TRANSITION)
    points = np.zeros((n, nf, 3))
    normals = np.zeros((n, nf, 3))
    for i in range(n):
        for c, f in enumerate(fingers):
            points[i, c], normals[i, c] = contact_of(f, Q[i, cut[c]:cut[c + 1]], pos[i], rho)
    specs = tuple(finger_spec(nm, f) for nm, f in zip(names, fingers, strict=True))
    refs = tuple(FingerReference(Q[:, cut[k]:cut[k + 1]], QD[:, cut[k]:cut[k + 1]], None,
                                 force[:, k]) for k in range(nf))
    contacts = tuple(ContactSpec(nm, "finger", nm, points[:, k], normals[:, k], active[:, k])
                     for k, nm in enumerate(names))
    load = problem.forces
    g = load.gravity
    plan = ExecutionPlan(ts, ObjectSpec(problem.object.shape,
                                        tuple(float(d) for d in problem.object.dimensions),
                                        float(load.mass)),
                         pos, wxyz, specs, refs, contacts, None, float(problem.mu), None,
                         (float(g[0]), float(g[1]), float(g[2])),
                         ("a gait: planned lift-offs and touch-downs (contacts' activity)",))
    plan.check()
    return plan
