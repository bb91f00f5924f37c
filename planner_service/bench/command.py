"""``dexroll bench SUITE``: run a suite of planning problems with every applicable method,
locally (a process pool), through a service (``--url``) or on Ray (``--ray``), and write a
report (see docs/benchmarks.md).

Exit code 0 when every run the suite expects to solve did (solved, certificate passed),
1 otherwise, 2 for a suite or option that cannot be used.
"""

from __future__ import annotations

import argparse
import datetime as dt
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

__all__ = ["add_arguments", "main", "run_bench"]

EXIT_OK, EXIT_UNEXPECTED, EXIT_USAGE = 0, 1, 2


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("suite", help="a shipped suite (quick, full) or a suite JSON file")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes (pool), jobs in flight (--url) or actors (--ray); "
                        "default: one per core (--ray: every CPU of the cluster)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--url", help="run through the dexroll service at this URL (the "
                                     "client), instead of the library")
    where.add_argument("--ray", metavar="ADDRESS",
                       help="run on Ray: a cluster address, 'auto' (the cluster this "
                            "machine belongs to) or 'local' (start a local instance)")
    p.add_argument("--out", help="report folder (default: bench-results/SUITE-<UTC time>)")
    p.add_argument("--methods", help="comma-separated subset of collocation, greedy, drake, "
                                     "casadi_plain (default: every applicable one)")
    p.add_argument("--families", help="comma-separated subset of the suite's families")
    p.add_argument("--limit", type=int, help="only the first K problems of each family")
    p.add_argument("--forces", metavar="MASS[,MIN_NORMAL[,TORSIONAL]]",
                   help="plan every finger request's contact forces (collocation: the "
                        "request's `forces` with this mass [kg], minimum normal force [N, "
                        "default 1] and torsional friction [m, default 0.005]); its "
                        "execution in MuJoCo then uses the plan's own forces alone")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--no-views", action="store_true",
                   help="no views of each family's best and worst plan beside the report "
                        "(they are planned again in this process; docs/viewer.md)")


def _split(text: str | None) -> list[str] | None:
    return None if text is None else [t.strip() for t in text.split(",") if t.strip()]


def forces_option(text: str | None) -> dict[str, float] | None:
    """The ``--forces`` option as a request's ``forces`` block (SuiteError when bad)."""
    from .suite import SuiteError

    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 3:
        raise SuiteError(f"--forces takes MASS[,MIN_NORMAL[,TORSIONAL]], got {text!r}")
    out = dict(zip(("mass", "min_normal_force", "torsional_friction"),
                   [*values, 1.0, 0.005][:3], strict=True))
    return out


def with_forces(todo: list[Any], forces: dict[str, float] | None) -> list[Any]:
    """The units with ``forces`` in the requests of the collocation method's finger
    planners (the greedy method and the palm's planners plan none)."""
    if forces is None:
        return todo
    return [replace(u, request={**u.request, "forces": dict(forces)})
            if u.method == "collocation" and u.planner in ("one_finger", "manipulation")
            else u for u in todo]


def run_bench(suite: str | Path, *, workers: int | None = None, url: str | None = None,
              ray: str | None = None, use_ray: bool = False, out: str | Path | None = None,
              methods: list[str] | None = None, families: list[str] | None = None,
              limit: int | None = None, progress: bool = True, views: bool = False,
              forces: dict[str, float] | None = None) -> tuple[int, dict[str, Any]]:
    """Run a suite and write its report; (exit code, the results document).

    ``url``: through that service; ``ray`` (an address, ``auto``, ``local``) or
    ``use_ray`` (the Ray instance this process has initialised): on Ray; else a local pool
    of ``workers`` processes. ``views``: write the views of each family's best and worst
    plan beside the report (``views/``, linked from it). ``forces``: every finger
    request's ``forces`` (:func:`with_forces`). Raises SuiteError for a suite, family or
    method that does not exist."""
    from .progress import Progress
    from .report import machine_info, now_utc, versions, write_report
    from .rows import peer_status
    from .runners import RayInfo, default_workers, run_pool, run_ray, run_service
    from .suite import METHODS, PEER_METHODS, SuiteError, expand, load_suite, units

    loaded = load_suite(suite)
    if methods is not None:
        unknown = sorted(set(methods) - set(METHODS))
        if unknown:
            raise SuiteError(f"unknown methods {unknown}; known: {list(METHODS)}")
    if limit is not None and limit < 1:
        raise SuiteError(f"--limit must be at least 1, got {limit}")
    started = now_utc()
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    out_dir = Path(out) if out is not None else Path("bench-results") / f"{loaded.name}-{stamp}"
    problems = expand(loaded, families, limit)
    todo = with_forces(units(problems, methods), forces)
    skipped: dict[str, str] = {}
    wanted_peers = {u.method for u in todo if u.method in PEER_METHODS}
    if wanted_peers:
        status = peer_status()
        skipped = {m: why for m in sorted(wanted_peers) if (why := status[m]) is not None}
        todo = [u for u in todo if u.method not in skipped]
    runner = "service" if url else "ray" if (ray or use_ray) else "pool"
    n_workers = workers or default_workers()
    bar = Progress(len(todo), enabled=progress)
    notes: list[str] = []
    ray_info = RayInfo()
    t0 = time.perf_counter()
    if runner == "service":
        assert url is not None
        rows = run_service(todo, url, n_workers, bar.update)
        if any(u.method in PEER_METHODS for u in todo):
            notes.append("the peers are not planners of the service: their runs were made "
                         "in this process with the library")
    elif runner == "ray":
        rows = run_ray(todo, ray, workers, bar.update, ray_info)
    else:
        rows = run_pool(todo, n_workers, bar.update)
    wall = time.perf_counter() - t0
    run: dict[str, Any] = {
        "runner": runner, "workers": int(ray_info.get("actors", n_workers)),
        "started": started, "finished": now_utc(), "wall_time": wall, "url": url,
        "methods": methods, "families": families, "limit": limit, "forces": forces,
        "notes": notes}
    if runner == "ray":
        run["ray"] = dict(ray_info)
    meta = {"suite": {"name": loaded.name, "source": loaded.source,
                      "description": loaded.description, "definition": loaded.data},
            "run": run, "machine": machine_info(), "versions": versions(),
            "skipped_methods": skipped}
    doc = write_report(out_dir, rows, meta, [
        {**asdict(p), "planner": p.planner} for p in problems], views=views)
    doc["out"] = str(out_dir)
    code = EXIT_UNEXPECTED if doc["unexpected_failures"] else EXIT_OK
    return code, doc


def main(args: argparse.Namespace) -> int:
    """The ``dexroll bench`` command."""
    from .suite import SuiteError

    try:
        code, doc = run_bench(args.suite, workers=args.workers, url=args.url, ray=args.ray,
                              out=args.out, methods=_split(args.methods),
                              families=_split(args.families), limit=args.limit,
                              progress=not args.no_progress, views=not args.no_views,
                              forces=forces_option(args.forces))
    except SuiteError as exc:
        print(f"dexroll bench: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ModuleNotFoundError as exc:
        if exc.name != "ray":
            raise
        print("dexroll bench: --ray needs ray (pip install 'dexroll[distributed]')",
              file=sys.stderr)
        return EXIT_USAGE
    for s in doc["summary"]:
        print(f"{s['family']:<16} {s['method']:<13} {s['ok']:>3}/{s['count']:<3} solved"
              + (f", solve median {s['solve_time_median']:.3f} s"
                 if s["solve_time_median"] is not None else ""))
    for m, why in doc["skipped_methods"].items():
        print(f"skipped {m}: {why}")
    for family, pid, method in doc["unexpected_failures"]:
        print(f"UNEXPECTED: {pid} ({family}, {method}) did not solve", file=sys.stderr)
    print(f"report       {Path(doc['out']) / 'report.md'}")
    return code
