"""How far a fingertip grasp can turn a ball: the built-in Allegro-class hand's four capsule
caps (r = 12 mm) rolling, without slip or spin, on a ball turned about a palm axis.

Three measurements, one table each (docs/hands.md, "How far a fingertip grasp can turn a
ball"):

1. ``cap``: the cap's own bound. If a tip's centre stayed where it is, rolling would move
   the contact over the cap by the same arc as over the ball, ``rho * theta * sin(axis,
   n)``; the cap offers the arc from the contact to its seam in that direction, at most
   ``pi r``. The turn that uses up the cap: ``theta_cap = arc / (rho sin(axis, n))``.
2. ``rolled``: each finger's motion as the ball's motion fixes it. No slip (the tip's
   material point at the contact moves with the ball's: 3 rows) and no spin (the tip's and
   the ball's angular velocities agree along the normal: 1 row) are 4 rows on the 4 joint
   rates of a 4-joint finger: a square system, integrated here (midpoint steps of at most
   0.25 deg, smaller where a joint moves fast, the ball's distance held by feedback)
   until a joint reaches its limit, the contact comes within 2 mm of its cap's seam (the
   planner's margin) or the motion folds ("singular"). The arcs travelled by the contact
   on the ball (in the ball's frame) and on the tip (in the tip's) are integrated too:
   they agree (the rolling law), and a tip's orbit about the ball is what lets the turn
   exceed the cap's bound.
3. ``plan``: the planner on the built-in hand's URDF, the same grasp, a turn of the measured
   reach less 1 deg and of the reach plus 3 deg about the axis (2 s, N = 20, tracked within
   1 mm / 1 deg, a 30 s limit): solved and certified or not.

Grasps: the shipped nominal grasp (a 60 mm ball), the same contact directions on balls of
40-70 mm (joints by least squares), and, per axis, the best grasp of a small search: per
finger, initial contacts sampled on the ball within 30 deg of the nominal contact's
direction (so that the four still oppose one another), each finger's motion rolled as in 2
(up to 120 deg), of each finger's 6 farthest the combination with the caps at least 1 mm
apart and the largest least reach (``ocp.robots.grasp_reach.search_grasp``; force closure
is the planner's certificate's).

    .venv/bin/python tools/hand_reach.py [--plan] [--samples 30] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ocp.robots.allegro import (
    NOMINAL_OBJECT_POSITION,
    NOMINAL_Q,
    NOMINAL_RADIUS,
    TIP_NAMES,
    load_allegro,
    urdf_text,
)
from ocp.robots.grasp_reach import (
    cap_bound,
    contact_sides,
    grasp_on_ball,
    roll,
    search_grasp,
    tip_state,
    tips_gap,
)

NAMES = ("index", "middle", "ring", "thumb")
AXES: dict[str, tuple[float, float, float]] = {
    "+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}
#: The arc [m] the planner keeps between a contact and its cap's seam (``pad_margin``).
MARGIN = 0.002


def plan(qs: Sequence[np.ndarray], hand: Any, c: np.ndarray, rho: float, axis: tuple[float, ...],
         angle: float) -> tuple[bool, str, float]:
    """Plan the turn with the built-in hand's URDF at the grasp ``qs``: (solved and
    certified, the status and message, the solve time [s])."""
    from planner_service.cli import plan_request

    tips = [{"name": name, "side": list(side)} for name, side in zip(
        TIP_NAMES, contact_sides(hand.fingers, qs, c, rho), strict=True)]
    req = {"planner": "manipulation", "object": {"shape": "sphere", "dimensions": [rho]},
           "hand": {"urdf": urdf_text(), "tips": tips},
           "fingers": [{"hand_finger": i, "initial_q": [float(x) for x in q]}
                       for i, q in enumerate(qs)],
           "initial_pose": {"position": [float(x) for x in c],
                            "orientation_wxyz": [1.0, 0.0, 0.0, 0.0]},
           "motion": {"kind": "steps", "steps": [{"duration": 2.0, "axis": list(axis),
                                                  "angle": angle}]},
           "tracking": {"position_tolerance": 0.001,
                        "orientation_tolerance": math.radians(1.0)},
           "duration": 2.0, "n_intervals": 20, "solver": {"time_limit": 30.0}}
    result, _ = plan_request(req)
    d = result.model_dump()
    ok = d.get("status") == "solved" and bool((d.get("certificate") or {}).get("passed"))
    solve = float((d.get("stats") or {}).get("solve_time") or math.nan)
    return ok, f"{d.get('status')}: {str(d.get('message'))[:80]}", solve


def _deg(x: float) -> str:
    return f"{math.degrees(x):.0f}" if math.isfinite(x) else "inf"


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--plan", action="store_true", help="check the reach by planning")
    parser.add_argument("--samples", type=int, default=30,
                        help="initial contacts tried per finger in the grasp search")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    hand = load_allegro()
    c = np.asarray(NOMINAL_OBJECT_POSITION, dtype=float)
    qn = [np.asarray(q, dtype=float) for q in NOMINAL_Q]

    print("## The nominal grasp (60 mm ball): cap bound, rolled reach, per finger [deg]\n")
    print("| axis | " + " | ".join(f"{n}: cap / rolled (stop)" for n in NAMES) +
          " | the hand |")
    print("|---|" + "---|" * (len(NAMES) + 1))
    law = []
    for name, axis in AXES.items():
        a = np.asarray(axis)
        cells, reach = [], math.inf
        for f, q, fn in zip(hand.fingers, qn, NAMES, strict=True):
            cb = cap_bound(f, q, c, NOMINAL_RADIUS, a)
            r = roll(f, q, c, NOMINAL_RADIUS, a, margin=MARGIN)
            reach = min(reach, r.reach)
            law.append((name, fn, r))
            cells.append(f"{_deg(cb)} / {_deg(r.reach)}" + (f" ({r.why})" if r.why else ""))
        print(f"| {name} | " + " | ".join(cells) + f" | {_deg(reach)} |")
    worst = max(abs(r.ball_arc - r.tip_arc) for _, _, r in law)
    print(f"\nrolling law along these motions: |ball arc - tip arc| <= {worst * 1e3:.3f} mm "
          f"(arcs up to {max(r.ball_arc for *_, r in law) * 1e3:.1f} mm; orbits up to "
          f"{_deg(max(r.orbit for *_, r in law))} deg)")
    print("\nstarting polar angle of each contact on its cap (0: the cap's end, 90: seam): " +
          ", ".join(f"{n} {math.degrees(tip_state(f, q, c, NOMINAL_RADIUS).polar):.0f}"
                    for f, q, n in zip(hand.fingers, qn, NAMES, strict=True)))

    print("\n## Other ball sizes, the nominal contact directions [deg, the hand's reach]\n")
    print("| ball | " + " | ".join(AXES) + " | caps' gap |")
    print("|---|" + "---|" * (len(AXES) + 1))
    normals = [tip_state(f, q, c, NOMINAL_RADIUS).n for f, q in zip(hand.fingers, qn,
                                                                     strict=True)]
    for diameter in (0.04, 0.05, 0.06, 0.07):
        rho = diameter / 2
        got = [grasp_on_ball(f, q, c, rho, n) for f, q, n in zip(hand.fingers, qn, normals,
                                                             strict=True)]
        if any(q is None for q in got):
            miss = [n for n, q in zip(NAMES, got, strict=True) if q is None]
            print(f"| {diameter * 1e3:.0f} mm | unreachable by {', '.join(miss)} |")
            continue
        qq = [q for q in got if q is not None]
        row = [_deg(min(roll(f, q, c, rho, np.asarray(a), margin=MARGIN).reach
                        for f, q in zip(hand.fingers, qq, strict=True)))
               for a in AXES.values()]
        print(f"| {diameter * 1e3:.0f} mm | " + " | ".join(row) +
              f" | {tips_gap(hand.fingers, qq) * 1e3:.1f} mm |")

    print(f"\n## The grasp search ({args.samples} initial contacts per finger within 30 deg "
          "of the nominal's, 60 mm ball) [deg]\n")
    print("| axis | grasp | per finger (" + ", ".join(NAMES) + ") | the hand | caps' gap | "
          "plan at reach - 1 | plan at reach + 3 |")
    print("|---|---|---|---|---|---|---|")
    for name, axis in AXES.items():
        a = np.asarray(axis)
        nominal = (qn, [roll(f, q, c, NOMINAL_RADIUS, a, margin=MARGIN)
                        for f, q in zip(hand.fingers, qn, strict=True)])
        found = search_grasp(hand.fingers, qn, c, NOMINAL_RADIUS, a, math.radians(120.0),
                             samples=args.samples, margin=MARGIN, seed=args.seed)
        for label, (qs, rolled) in (("nominal", nominal),
                                    ("searched", (list(found.q), list(found.rolled)))):
            reach = min(r.reach for r in rolled)
            plans = ["-", "-"]
            if args.plan:
                for k, extra in enumerate((-1.0, 3.0)):
                    angle = max(math.radians(1.0), reach + math.radians(extra))
                    t0 = time.perf_counter()
                    ok, msg, solve = plan(qs, hand, c, NOMINAL_RADIUS, axis, angle)
                    plans[k] = (f"{_deg(angle)}: {'certified' if ok else 'no'} "
                                f"(IPOPT {solve:.1f} s, wall {time.perf_counter() - t0:.0f} s)")
                    if not ok:
                        plans[k] += f" {msg}"
            print(f"| {name} | {label} | "
                  + ", ".join(f"{_deg(r.reach)}" + (f" ({r.why})" if r.why else "")
                              for r in rolled)
                  + f" | {_deg(reach)} | {tips_gap(hand.fingers, qs) * 1e3:.1f} mm | {plans[0]} | "
                  f"{plans[1]} |")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
