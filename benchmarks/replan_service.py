"""Re-plan latency through the service on loopback (issue 28, part 3; docs/replanning.md
"Through the service").

Starts a real service (`dexroll serve`: uvicorn on 127.0.0.1, a fresh data folder, one
solver worker), plans each experiment through it (sampled at the controller's RATE), then
plays a remote controller: for each sample time from START on, ``POST
/v1/plans/{id}/replan`` with the plan's own joints and the object's pose there, the pose
with Gaussian noise (NOISE mm, one seed: every re-plan must correct a little), the
controller's calls one after the other as a 20 Hz loop makes them. The first call builds
the plan's re-planner (reported apart); the others are the latency a controller sees:
the client's wall clock per call (HTTP, the pipes to the re-plan process, the estimate,
IPOPT, the answer's samples) and the re-plan process's own wall time beside it. Prints a
Markdown table (median and p90) and writes every call's figures as JSON.

    PYTHONPATH=.:clients/python .venv/bin/python benchmarks/replan_service.py \
        [--calls 25] [--only "experiment 1"] [--out replan_service.json]
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
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: (name, request file, the first re-plan's time [s])
PLANS = [("experiment 1", "docs/viewer-experiment1.json", 0.5),
         ("experiment 2", "examples/experiment2_two_fingers.json", 0.5)]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _serve(data: Path) -> tuple[subprocess.Popen[bytes], str]:
    port = _free_port()
    env = {**os.environ, "DEXROLL_HOST": "127.0.0.1", "DEXROLL_PORT": str(port),
           "DEXROLL_DATA_DIR": str(data), "DEXROLL_WORKERS": "1", "DEXROLL_WARMUP": ""}
    log = (data / "server.log").open("wb")
    proc = subprocess.Popen([sys.executable, "-m", "planner_service.cli", "serve"], env=env,
                            stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/readyz", timeout=2).status_code == 200:
                return proc, url
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    proc.kill()
    raise RuntimeError("the service did not start")


def _plan(client: httpx.Client, request: dict[str, Any]) -> dict[str, Any]:
    r = client.post("/v1/plans", json=request, params={"wait": 30})
    job = r.json()
    while job["state"] in ("queued", "running"):
        time.sleep(0.5)
        job = client.get(f"/v1/plans/{job['id']}").json()
    if job["state"] != "succeeded":
        raise RuntimeError(f"the plan ended {job['state']}: {job.get('message')}")
    return dict(job)


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def run(client: httpx.Client, name: str, path: str, start: float, calls: int, rate: float,
        noise: float, seed: int) -> dict[str, Any]:
    request = json.loads((ROOT / path).read_text())
    request["sample_rate"] = rate
    t0 = time.perf_counter()
    job = _plan(client, request)
    plan_s = time.perf_counter() - t0
    smp = job["result"]["samples"]
    rng = np.random.default_rng(seed)
    ts = np.asarray(smp["t"])
    first = int(np.searchsorted(ts, start - 1e-9))
    rows = []
    for n, k in enumerate(range(first, min(first + calls + 1, len(ts) - 1))):
        pos = np.asarray(smp["object_position"][k]) + (rng.normal(0.0, noise, 3)
                                                        if n else 0.0)
        body = {"t": float(ts[k]), "q": [f["q"][k] for f in smp["fingers"]],
                "object_position": pos.tolist(),
                "object_wxyz": smp["object_orientation_wxyz"][k], "max_iter": 30,
                "time_limit": 10.0}
        c0 = time.perf_counter()
        r = client.post(f"/v1/plans/{job['id']}/replan", json=body, timeout=600)
        wall = time.perf_counter() - c0
        d = r.json()
        if r.status_code != 200:
            rows.append({"t": body["t"], "http": r.status_code, "error": d.get("error"),
                         "client_s": wall})
            continue
        s = d["stats"]
        rows.append({"t": body["t"], "status": d["status"], "client_s": wall,
                     "process_s": s["wall_time"], "ipopt_s": s["solve_time"],
                     "estimate_s": s["estimate_time"], "setup_s": s["setup_time"],
                     "iterations": s["iterations"], "converged": s["converged"],
                     "bytes": len(r.content)})
    warm = [r for r in rows[1:] if r.get("status") == "replanned"]
    out: dict[str, Any] = {"plan": name, "plan_s": plan_s, "first_call_s": rows[0]["client_s"],
                           "setup_s": rows[0].get("setup_s"), "calls": rows}
    if warm:
        c = [r["client_s"] for r in warm]
        p = [r["process_s"] for r in warm]
        out.update(n=len(warm), client_median=statistics.median(c), client_p90=_pct(c, 90),
                   process_median=statistics.median(p), process_p90=_pct(p, 90),
                   iterations_median=statistics.median(r["iterations"] for r in warm),
                   statuses={s: sum(1 for r in rows[1:] if r.get("status", r.get("error"))
                                    == s) for s in {r.get("status", r.get("error"))
                                                    for r in rows[1:]}})
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=25, help="warm re-plans per plan")
    ap.add_argument("--rate", type=float, default=20.0, help="the controller's rate [Hz]")
    ap.add_argument("--noise", type=float, default=0.2, help="pose noise [mm]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--out", default="replan_service.json")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        proc, url = _serve(Path(tmp))
        try:
            with httpx.Client(base_url=url, timeout=600) as client:
                print("| plan | first call [s] (setup) | warm re-plans | client median / p90 "
                      "[ms] | re-plan process median / p90 [ms] | iterations (median) |")
                print("|---|---|---|---|---|---|")
                for name, path, start in PLANS:
                    if args.only and name not in args.only:
                        continue
                    row = run(client, name, path, start, args.calls, args.rate,
                              args.noise * 1e-3, args.seed)
                    rows.append(row)
                    Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")
                    if "n" not in row:
                        print(f"| {name} | {row['first_call_s']:.2f} | none converged | | |")
                        continue
                    print(f"| {name} | {row['first_call_s']:.2f} ({row['setup_s']:.2f}) | "
                          f"{row['n']} {row['statuses']} | "
                          f"{1e3 * row['client_median']:.0f} / {1e3 * row['client_p90']:.0f} | "
                          f"{1e3 * row['process_median']:.0f} / "
                          f"{1e3 * row['process_p90']:.0f} | {row['iterations_median']} |",
                          flush=True)
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    return 0


if __name__ == "__main__":
    sys.exit(main())
