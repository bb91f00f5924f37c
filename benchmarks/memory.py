"""Memory of a planning process over many solves: is it flat?

Plans the same requests over and over in one process, as a service worker does (the
process-wide planners and caches of ``planner_service.planners``), and samples the resident
set size (VmRSS, from /proc) every ``--every`` solves. A leak shows as a steady climb; a
flat curve after the first solves (caches filled) is what a worker should show.

    .venv/bin/python benchmarks/memory.py [--solves 1000] [--every 100]
        [--requests triangle.json,one_finger_roll.json] [--out benchmarks/results]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--solves", type=int, default=1000)
    parser.add_argument("--every", type=int, default=100)
    parser.add_argument("--requests", default="triangle.json")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = parser.parse_args(argv)
    from planner_service.planners import REQUEST, solve

    requests = [REQUEST.validate_python(json.loads((ROOT / "examples" / n).read_text()))
                for n in args.requests.split(",")]
    samples = [{"solves": 0, "rss_mb": rss_mb()}]
    t0 = time.perf_counter()
    for i in range(1, args.solves + 1):
        result, _ = solve(requests[i % len(requests)])
        if result.status.value != "solved":
            raise RuntimeError(f"solve {i} not solved: {result.message}")
        if i % args.every == 0:
            samples.append({"solves": i, "rss_mb": rss_mb()})
    after_first = samples[1]["rss_mb"]
    report = {"requests": args.requests, "solves": args.solves,
              "wall_s": time.perf_counter() - t0, "samples": samples,
              "growth_after_first_sample_mb": samples[-1]["rss_mb"] - after_first}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "memory.json").write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
