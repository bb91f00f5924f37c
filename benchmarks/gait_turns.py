"""The issue's target turns of finger gaiting, timed (docs/gait.md, docs/performance.md).

The turns: ``examples/allegro_turn_90.json`` (the built-in hand, the 60 mm, 50 g ball,
mu = 1.0, a searched grasp, rolls of at most 10 deg) with its axis set to each of +-x, +-y
and +-z; ``examples/allegro_turn_180_z.json``; 90 deg about +x on
``examples/own_hand.xml`` given as MJCF text.

Each run is one fresh process that plans every turn in turn, as a service worker does (the
first request pays the swing NLPs' construction; each searched grasp is a new hand model,
so each request builds its roll NLP). Per turn it reports the plan (status, certificate,
rolls, re-placements) and, as medians over ``--repeats`` runs:

- ``wall``: the whole request (validation, grasp search, builds, the gait, the result's
  samples), what a client waits for;
- ``build``: constructing NLPs, apart: the swing NLPs (``prepare_swings``) and the rolls'
  (``stats.build_time``);
- ``solve``: the solver calls (``stats.solve_time``: the rolls' IPOPT, force stages
  included, and the swings');
- ``other``: the rest of the gait (reach predictions, holds, certificates, samples).

With ``--ref REV`` the same runs are made at git commit REV (a worktree under the system's
temporary directory), interleaved with this tree's (old, new, old, new, ...), and both are
printed side by side.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/gait_turns.py --repeats 3
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/gait_turns.py --ref 1d51bdd --repeats 2
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/gait_turns.py --replace --repeats 1
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/gait_turns.py --fast --repeats 1
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/gait_turns.py --shapes --warm --ref HEAD~1
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/gait_turns.py --options overlap --warm \
        --ref HEAD~1 --repeats 1

``--shapes`` times the gaits of an egg, a capsule and a rounded cube (:func:`shape_targets`)
instead; with ``--ref`` old and new side by side as for the ball's. ``--warm`` times each
turn the second time its process plans it (a warm worker's request).

``--replace`` plans every turn with the request's ``gait.replace`` "all" and "spent" side
by side instead (robot time and re-placements are the plans', the same every run);
``--fast`` with the requests' own gait options and with :data:`FAST`'s (spent
re-placements, fastest swings and rolls); ``--farthest`` :data:`FAST`'s against
:data:`FARTHEST`'s (spent fingertips landing where they roll farthest, rolls of up to
30 deg); ``--overlap`` :data:`FARTHEST`'s against :data:`OVERLAP`'s (the spent fingertips
re-placed while the others roll).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
AXES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
        "+z": (0, 0, 1), "-z": (0, 0, -1)}


def targets(root: Path = ROOT) -> dict[str, dict[str, Any]]:
    """The requests of the target turns, by name, from the examples under ``root``."""
    base = json.loads((root / "examples" / "allegro_turn_90.json").read_text())
    out: dict[str, dict[str, Any]] = {}
    for name, axis in AXES.items():
        req = json.loads(json.dumps(base))
        req["motion"]["steps"][0]["axis"] = list(axis)
        out[f"90 {name}"] = req
    out["180 +z"] = json.loads((root / "examples" / "allegro_turn_180_z.json").read_text())
    own = json.loads(json.dumps(base))
    own["hand"] = {"mjcf": (root / "examples" / "own_hand.xml").read_text(),
                   "tips": [{"name": n} for n in ("ff_tip", "mf_tip", "rf_tip", "th_tip")]}
    out["90 +x MJCF"] = own
    return out


def shape_targets(root: Path = ROOT) -> dict[str, dict[str, Any]]:
    """``--shapes``: gaits of objects that are not balls (issue 38's bound: a 90 deg gait
    of a non-sphere planned within 30 s on a warm worker), by name: the egg lying across
    the fingers turned 90 deg about +x from a searched grasp (``examples/egg_gait.json``),
    the upright capsule of ``examples/capsule_roll.json`` turned 90 deg about its axis in
    rolls of 5 deg, and the rounded cube of ``examples/rounded_cube_turn.json`` turned 30
    deg about +z in rolls of 10 deg."""
    egg = json.loads((root / "examples" / "egg_gait.json").read_text())
    capsule = json.loads((root / "examples" / "capsule_roll.json").read_text())
    capsule["motion"]["steps"][0].update(axis=[0, 0, -1], angle=1.570796, duration=9.0)
    capsule.update(duration=9.0, gait={"roll_step": 0.0872665})
    cube = json.loads((root / "examples" / "rounded_cube_turn.json").read_text())
    cube["motion"]["steps"][0].update(axis=[0, 0, 1], angle=0.523599, duration=3.0)
    cube.update(duration=3.0, gait={"roll_step": 0.174533})
    return {"egg 90 +x": egg, "capsule 90 -z": capsule, "cube 30 +z": cube}


#: The gait options of ``--fast``: only spent fingertips re-placed, swings and rolls as fast
#: as the hand allows (the holds' force ramps as the request's: with 0.1 s instead of 0.2 s,
#: 3 of the 8 turns lost a contact for 1.5-4.5 ms at a load in MuJoCo; docs/gait.md).
FAST = {"replace": "spent", "fastest_swings": True, "fastest_rolls": True}
#: ``--farthest``: FAST with the spent fingertips landing where they roll farthest, and
#: rolls of up to 30 deg.
FARTHEST = {**FAST, "landing": "farthest", "roll_step": 0.5236}
#: ``--overlap``: FARTHEST with the spent fingertips re-placed while the others roll.
OVERLAP = {**FARTHEST, "overlap": True}


def _worker(names: list[str], options: dict[str, Any] | None = None,
            warm: bool = False) -> None:
    """One run: every named turn planned in this process, one JSON line each
    (``options``: fields set in the requests' ``gait``, default theirs; ``warm``: each
    turn planned once untimed before, as a worker that has planned it)."""
    from ocp.gait.swing import prepare_swings
    from planner_service.planners.cache import FINGERS
    from planner_service.planners.gait import solve_gait

    reqs = {**targets(Path.cwd()), **shape_targets(Path.cwd())}
    for name in names:
        reqs[name]["gait"].update(options or {})
        if warm:  # (its swing NLPs as below, then the gait's own)
            req, problem = _problem(reqs[name])
            prepare_swings(tuple(tip.finger for tip in problem.fingers))
            solve_gait(req, problem, FINGERS.manipulation)
        t0 = time.perf_counter()
        req, problem = _problem(reqs[name])
        t1 = time.perf_counter()
        swings = prepare_swings(tuple(tip.finger for tip in problem.fingers))
        t2 = time.perf_counter()
        res, gait = solve_gait(req, problem, FINGERS.manipulation)
        t3 = time.perf_counter()
        assert res.stats is not None
        print(json.dumps({
            "name": name, "status": res.status.value,
            "certified": bool(res.certificate is not None and res.certificate.passed),
            "rolls": len(gait.rolls), "replacements": gait.replacements,
            "during_rolls": len(gait.carried),
            "robot": gait.duration if gait.phases else None,
            "wall": t3 - t0, "grasp": t1 - t0, "swing_build": swings,
            "roll_build": res.stats.build_time, "solve": res.stats.solve_time,
            "gait": t3 - t2}), flush=True)


def _problem(raw: dict[str, Any]) -> tuple[Any, Any]:
    """A request's (validated request, problem with its grasp)."""
    from dexroll_client import ManipulationRequest
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FINGERS
    from planner_service.planners.manipulation import problem_and_grasp

    req = REQUEST.validate_python(raw)
    assert isinstance(req, ManipulationRequest)
    return req, problem_and_grasp(req, FINGERS)[0]


def _run(tree: Path, names: list[str], gait: dict[str, Any] | None = None,
         warm: bool = False) -> list[dict[str, Any]]:
    """One run in a fresh process whose ``ocp`` and ``planner_service`` are ``tree``'s
    (``gait``: fields set in the requests' ``gait``; ``warm``: each turn timed the
    second time it is planned)."""
    # a service worker's threads (planner_service.executors.worker_env: one each; with
    # OpenMP's default of one thread per core, MUMPS's BLAS contended with the planner's
    # own process on this 2-core machine)
    env = {**os.environ, "PYTHONPATH": str(tree),
           **{k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}}
    extra = ([] if not gait else ["--worker-gait", json.dumps(gait)]) + \
        (["--worker-warm"] if warm else [])
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), *extra,
                          "--worker", *names], cwd=tree, env=env, capture_output=True,
                         text=True, check=True)
    return [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]


def _worktree(rev: str) -> Path:
    path = Path(tempfile.gettempdir()) / f"dexroll-gait-turns-{rev}"
    if not path.exists():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path),
                        rev], check=True, capture_output=True)
    return path


def _median(rows: list[dict[str, Any]], key: str) -> float:
    return statistics.median(float(r[key]) for r in rows)


def _table(sides: dict[str, list[list[dict[str, Any]]]]) -> str:
    lines = ["| turn | side | status, certified | rolls, re-placements | robot time [s] | "
             "wall [s] | grasp [s] | swing build [s] | roll build [s] | solve [s] | "
             "other [s] |",
             "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    names = [r["name"] for r in next(iter(sides.values()))[0]]
    for name in names:
        for side, runs in sides.items():
            rows = [r for run in runs for r in run if r["name"] == name]
            other = [r["gait"] - r["solve"] - r["roll_build"] for r in rows]
            during = rows[0].get("during_rolls") or 0
            carried = f" ({during} during rolls)" if during else ""
            lines.append(
                f"| {name} | {side} | {rows[0]['status']}, {rows[0]['certified']} | "
                f"{rows[0]['rolls']}, {rows[0]['replacements']}{carried} | "
                f"{rows[0].get('robot') or float('nan'):.1f} | "
                f"{_median(rows, 'wall'):.1f} | {_median(rows, 'grasp'):.1f} | "
                f"{_median(rows, 'swing_build'):.1f} | {_median(rows, 'roll_build'):.1f} | "
                f"{_median(rows, 'solve'):.1f} | {statistics.median(other):.1f} |")
    axes = [n for n in names if n.startswith("90 ") and "MJCF" not in n]
    for side, runs in sides.items() if axes else ():  # (--turns may leave none)
        def over_axes(key: str, runs: list[list[dict[str, Any]]] = runs) -> float:
            """The median over the 90 deg axis turns of each turn's median ``key``."""
            return statistics.median(_median([r for run in runs for r in run
                                              if r["name"] == n], key) for n in axes)

        lines.append(f"\n{side}: the six 90 deg turns' median wall "
                     f"{over_axes('wall'):.1f} s, median solve {over_axes('solve'):.1f} s")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="runs per side (median)")
    ap.add_argument("--ref", default=None, help="a git commit to time side by side")
    ap.add_argument("--turns", default=None,
                    help="comma-separated subset of the turns (default: all)")
    ap.add_argument("--out", default=None, help="write every run's rows as JSON here")
    ap.add_argument("--replace", action="store_true",
                    help="time gait.replace 'all' and 'spent' side by side (this tree)")
    ap.add_argument("--fast", action="store_true",
                    help="time the requests as they are and with FAST's gait options "
                         "side by side (this tree)")
    ap.add_argument("--farthest", action="store_true",
                    help="time FAST's and FARTHEST's gait options side by side (this tree)")
    ap.add_argument("--overlap", action="store_true",
                    help="time FARTHEST's and OVERLAP's gait options side by side (this "
                         "tree)")
    ap.add_argument("--options", choices=("fast", "farthest", "overlap"), default=None,
                    help="plan both sides (this tree, and --ref's) with FAST's, FARTHEST's "
                         "or OVERLAP's gait options instead of the requests' own")
    ap.add_argument("--shapes", action="store_true",
                    help="the gaits of other shapes (shape_targets) instead of the ball's")
    ap.add_argument("--warm", action="store_true",
                    help="time each turn the second time its process plans it (a warm "
                         "worker's; default: the first)")
    ap.add_argument("--worker", nargs="*", help=argparse.SUPPRESS)
    ap.add_argument("--worker-warm", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--worker-gait", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker is not None:
        _worker(args.worker, json.loads(args.worker_gait) if args.worker_gait else None,
                args.worker_warm)
        return
    names = list(shape_targets() if args.shapes else targets())
    if args.turns:
        names = [n for n in names if n in args.turns.split(",")]
    chosen = {"fast": FAST, "farthest": FARTHEST, "overlap": OVERLAP}.get(args.options or "")
    runs: dict[str, tuple[Path, dict[str, Any] | None]] = \
        {"all": (ROOT, {"replace": "all"}), "spent": (ROOT, {"replace": "spent"})} \
        if args.replace else {"default": (ROOT, None), "fast": (ROOT, FAST)} if args.fast \
        else {"fast": (ROOT, FAST), "farthest": (ROOT, FARTHEST)} if args.farthest \
        else {"farthest": (ROOT, FARTHEST), "overlap": (ROOT, OVERLAP)} if args.overlap \
        else {"new": (ROOT, chosen)} if args.ref is None else \
        {"old": (_worktree(args.ref), chosen), "new": (ROOT, chosen)}
    sides: dict[str, list[list[dict[str, Any]]]] = {side: [] for side in runs}
    for k in range(args.repeats):
        for side, (tree, gait) in runs.items():
            print(f"run {k + 1}/{args.repeats}, {side}", file=sys.stderr, flush=True)
            sides[side].append(_run(tree, names, gait, args.warm))
    if args.out:
        Path(args.out).write_text(json.dumps(sides, indent=1))
    print(_table(sides))


if __name__ == "__main__":
    main()
