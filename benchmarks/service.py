"""Service figures: start-up, time to first plan, HTTP overhead, worker memory.

Starts real services (`dexroll serve` on a free loopback port, fresh data folder) and
measures, for a fresh service with and without the warm-up (``DEXROLL_WARMUP``):

* time until ``/readyz`` answers 200 (spawned workers import CasADi and Pinocchio, then
  build the warm-up structures);
* time to the first plan of each example request (``POST /v1/plans?wait=``, wall clock at
  the client), and the plan's own NLP build time (0 when it came from the cache);
* the HTTP round trip against the solve: for experiment 1 (``--repeat`` requests after
  the first), the client's wall clock per plan against the same request planned in-process
  by the library with its caches warm, the two interleaved (one request, one in-process
  plan, ...) so that the machine's drift affects both alike (median of each); the ratio
  is the overhead. The in-process plans run with one BLAS thread, as the workers do;
* peak RSS (VmHWM) of each worker process at the end, from /proc.

    .venv/bin/python benchmarks/service.py [--repeat 5] [--out benchmarks/results]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
FIRST = ("triangle.json", "one_finger_roll.json", "experiment2_two_fingers.json")


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _vm_hwm_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def experiment1_request() -> dict[str, Any]:
    """experiments/experiment1.py's problem as a one_finger request."""
    e = json.loads((EXAMPLES / "one_finger_roll.json").read_text())
    e.update(initial={"x": 0.0, "y": 0.0, "u": 0.0, "v": 0.0, "psi": -1.5707963267948966},
             goal={"x": 0.0, "y": 0.0}, duration=6.0, n_intervals=60,
             via_points=[{"time": 2.0, "coords": {"x": 0.03, "y": 0.0}},
                         {"time": 4.0, "coords": {"x": 0.03, "y": 0.03}}])
    return e


def post(url: str, body: dict[str, Any]) -> tuple[float, dict[str, Any]]:
    t0 = time.perf_counter()
    r = httpx.post(f"{url}/v1/plans", params={"wait": 120}, json=body, timeout=180)
    wall = time.perf_counter() - t0
    job: dict[str, Any] = r.json()
    if r.status_code != 201 or job.get("state") != "succeeded":
        raise RuntimeError(f"plan failed: {r.status_code} {str(job)[:300]}")
    return wall, job


def run_service(warmup: str, repeat: int) -> dict[str, Any]:
    library = _library_experiment1()
    port = _port()
    data = Path(tempfile.mkdtemp(prefix="dexroll-bench-"))
    env = {**os.environ, "DEXROLL_PORT": str(port), "DEXROLL_DATA_DIR": str(data),
           "DEXROLL_WORKERS": "2", "DEXROLL_WARMUP": warmup}
    url = f"http://127.0.0.1:{port}"
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "planner_service.cli", "serve"], env=env,
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while True:
            if proc.poll() is not None:
                raise RuntimeError("the service exited at start")
            try:
                if httpx.get(f"{url}/readyz", timeout=2).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        ready = time.perf_counter() - t0
        first: dict[str, Any] = {}
        pids: set[int] = set()
        for name in FIRST:
            wall, job = post(url, json.loads((EXAMPLES / name).read_text()))
            stats = job["result"]["stats"]
            first[name] = {"wall_s": wall, "build_s": stats["build_time"],
                           "solve_s": stats["solve_time"]}
            pids.add(int(job["worker_pid"]))
        request = experiment1_request()
        walls, solves, in_process = [], [], []
        post(url, request)  # builds or warms this structure in one worker
        post(url, request)  # and in the other (two workers, jobs alternate when idle)
        for _ in range(repeat):
            wall, job = post(url, request)
            walls.append(wall)
            solves.append(job["result"]["stats"]["solve_time"])
            pids.add(int(job["worker_pid"]))
            in_process.append(library())
        http, lib = statistics.median(walls), statistics.median(in_process)
        return {"warmup": warmup or "(none)", "ready_s": ready, "first_plans": first,
                "experiment1_http_wall_median_s": http,
                "experiment1_ipopt_median_s": statistics.median(solves),
                "library_experiment1_wall_median_s": lib,
                "experiment1_http_overhead": http / lib - 1.0,
                "worker_peak_rss_mb": {str(p): _vm_hwm_mb(p) for p in sorted(pids)}}
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _library_experiment1() -> Any:
    """A function planning experiment 1 in-process (caches warm after a first plan) and
    returning its wall clock [s]."""
    from planner_service.planners import REQUEST, solve

    request = REQUEST.validate_python(experiment1_request())
    solve(request)

    def plan() -> float:
        t0 = time.perf_counter()
        solve(request)
        return time.perf_counter() - t0

    return plan


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = parser.parse_args(argv)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")  # before the library loads CasADi: as the workers
    report: dict[str, Any] = {"cold": run_service("", args.repeat),
                              "warm": run_service(str(EXAMPLES), args.repeat)}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "service.json").write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
