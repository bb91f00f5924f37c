"""How far rolling alone can turn a ball held by the built-in Allegro-class hand's four caps.

A finger of 4 joints rolling on the object has 4 + 2 rates for the 6 rows of its closure,
so the object's motion fixes each finger's motion (docs/hands.md). This script integrates
each finger's fixed motion (the initial guess's integrator,
``ocp.solve.contact_guesses.integrated_guess``: the contact inputs and joint rates that keep
d/dt closure = 0) from the hand's nominal grasp while the ball turns about each palm axis,
both ways, up to ``--angle`` degrees, and reports for each finger the angle at which it
first reaches a joint limit (within 0.01 rad), leaves its cap (within 0.05 rad of the
seam) or reaches its chart's pole bound: the largest turn a plan tracking the motion
within a degree can make from that grasp.

    .venv/bin/python benchmarks/round_tip_reach.py [--angle 90] [--samples 46]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ocp.contacts import FingertipContact
from ocp.geometry.surfaces import Sphere, rotation_from_vector
from ocp.robots.allegro import NOMINAL_OBJECT_POSITION, NOMINAL_Q, NOMINAL_RADIUS, load_allegro
from ocp.solve.contact_guesses import integrated_guess
from ocp.spec.grasp import ManipulationProblem, fingertips_from_joints
from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose
from ocp.spec.problem import ObjectSpec

NAMES = ("index", "middle", "ring", "thumb")


def reach(axis: tuple[float, float, float], angle_deg: float, samples: int
          ) -> dict[str, tuple[float, str]]:
    """Per finger: (the angle [deg] it reaches before a limit, which limit or '')."""
    hand = load_allegro()
    obj = ObjectSpec("sphere", (NOMINAL_RADIUS,))
    pose = ObjectPose(position=NOMINAL_OBJECT_POSITION)
    tips = fingertips_from_joints(hand.fingers, NOMINAL_Q, obj, pose, NAMES, NAMES)
    motion = DesiredMotion.from_steps(pose, [MotionStep(1.0, axis, math.radians(angle_deg))],
                                      smooth=False)
    problem = ManipulationProblem(obj, tips, 1.0, initial_pose=pose, motion=motion)
    ts = np.linspace(0.0, 1.0, samples)
    out = {}
    for i, tip in enumerate(tips):
        contact = FingertipContact(Sphere, tip.finger, i)
        eta, _, q = integrated_guess(contact, problem, motion.at, ts,
                                     rotation_from_vector(tip.chart_rotation),
                                     np.array([NOMINAL_RADIUS]))
        f = tip.finger
        margin = np.min(np.minimum(q - f.lower, f.upper - q), axis=1)
        (a_lo, a_hi), (b_lo, b_hi) = f.tip_surface.bounds(0.0, math.radians(15.0))
        why = np.where(margin < 0.01, "joint limit", np.where(
            (eta[:, 1] < b_lo + 0.05) | (eta[:, 1] > b_hi - 0.05), "cap's seam", np.where(
                (eta[:, 0] < a_lo) | (eta[:, 0] > a_hi), "tip chart's pole", "")))
        bad = np.flatnonzero(why != "")
        k = int(bad[0]) if bad.size else len(ts)
        out[tip.name] = (angle_deg * (k - 1) / (samples - 1) if k < len(ts) else angle_deg,
                         str(why[k]) if k < len(ts) else "")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--angle", type=float, default=90.0)
    parser.add_argument("--samples", type=int, default=46)
    args = parser.parse_args()
    print(f"| axis | {' | '.join(NAMES)} | the hand |")
    print("|---|" + "---|" * (len(NAMES) + 1))
    for name, axis in (("+x", (1.0, 0.0, 0.0)), ("-x", (-1.0, 0.0, 0.0)),
                       ("+y", (0.0, 1.0, 0.0)), ("-y", (0.0, -1.0, 0.0)),
                       ("+z", (0.0, 0.0, 1.0)), ("-z", (0.0, 0.0, -1.0))):
        per = reach(axis, args.angle, args.samples)
        cells = [f"{a:.0f} deg" + (f" ({w})" if w else "") for a, w in per.values()]
        print(f"| {name} | {' | '.join(cells)} | {min(a for a, _ in per.values()):.0f} deg |")


if __name__ == "__main__":
    main()
