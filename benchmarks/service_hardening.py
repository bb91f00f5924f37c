"""The service's hardening figures (issue 17), each against a real `dexroll serve` on
loopback: run by hand, print one JSON line per measurement.

    python benchmarks/service_hardening.py healthz     # /healthz while a 400-joint URDF is refused
    python benchmarks/service_hardening.py deadlines   # 20 jobs with time_limit 1 s: lateness
    python benchmarks/service_hardening.py results     # 40 concurrent GETs of a large result
    python benchmarks/service_hardening.py clients     # 200 concurrent clients: lost/dup jobs
    python benchmarks/service_hardening.py simulations # 40 long simulations: API latency
    python benchmarks/service_hardening.py models      # 24 hand URDFs: a plain POST's latency
    python benchmarks/service_hardening.py batch [-n 200 --sims 48]  # a batch and simulations

``--src DIR`` runs the service from another checkout (``git worktree add /tmp/base <rev>``)
to measure the code before a change with the same interpreter and packages.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import contextlib
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def chain_urdf(n: int) -> str:
    """A serial chain of ``n`` revolute joints ending in a ``fingertip`` link."""
    parts = ['<robot name="chain"><link name="l0"/>']
    for i in range(n):
        parts.append(
            f'<link name="l{i + 1}"/><joint name="j{i}" type="revolute">'
            f'<parent link="l{i}"/><child link="l{i + 1}"/><origin xyz="0 0 0.001"/>'
            '<axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')
    parts.append(f'<link name="fingertip"/><joint name="tip" type="fixed"><parent link="l{n}"/>'
                 '<child link="fingertip"/></joint></robot>')
    return "".join(parts)


def finger_request(urdf: str) -> dict[str, Any]:
    req: dict[str, Any] = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    req["finger"] = {"urdf": urdf, "tip_frame": "fingertip"}
    return req


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Service:
    def __init__(self, src: Path | None, **env: str) -> None:
        self.data = Path(tempfile.mkdtemp(prefix="dexroll-bench-"))
        self.port = _port()
        self.url = f"http://127.0.0.1:{self.port}"
        environ = {**os.environ, "DEXROLL_PORT": str(self.port), "DEXROLL_DATA_DIR":
                   str(self.data), "DEXROLL_WORKERS": "2", "DEXROLL_WARMUP": "", **env}
        if src is not None:
            environ["PYTHONPATH"] = f"{src}:{src / 'clients' / 'python'}"
        self.log = (self.data / "server.log").open("wb")
        self.proc = subprocess.Popen([sys.executable, "-m", "planner_service.cli", "serve"],
                                     env=environ, stdout=self.log, stderr=subprocess.STDOUT,
                                     cwd=src or ROOT)
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{self.url}/readyz", timeout=2).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        raise RuntimeError("service not ready")

    def cpu_and_wait_s(self) -> tuple[float, float]:
        """The API process's CPU time so far and the time its threads waited for a CPU
        (run queue: /proc/<pid>/task/*/schedstat), both in seconds."""
        cpu = wait = 0.0
        for task in Path(f"/proc/{self.proc.pid}/task").iterdir():
            try:
                run, delay, _ = (task / "schedstat").read_text().split()
            except (OSError, ValueError):
                continue
            cpu += int(run) / 1e9
            wait += int(delay) / 1e9
        return cpu, wait

    def rss_mb(self) -> float:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(30)


class Prober(threading.Thread):
    """Polls /healthz every 20 ms and samples the API's RSS meanwhile."""

    def __init__(self, service: Service) -> None:
        super().__init__(daemon=True)
        self.service, self.latencies, self.rss = service, [], []  # type: ignore[var-annotated]
        self.stop = threading.Event()

    def run(self) -> None:
        with httpx.Client(timeout=60) as http:
            while not self.stop.is_set():
                t0 = time.perf_counter()
                http.get(f"{self.service.url}/healthz")
                self.latencies.append(time.perf_counter() - t0)
                self.rss.append(self.service.rss_mb())
                time.sleep(0.02)

    def summary(self) -> dict[str, float]:
        return {"healthz_max_s": round(max(self.latencies), 4),
                "healthz_median_s": round(statistics.median(self.latencies), 4),
                "api_rss_max_mb": round(max(self.rss), 1)}


def bench_healthz(svc: Service, joints: int) -> dict[str, Any]:
    probe = Prober(svc)
    probe.start()
    time.sleep(0.3)
    t0 = time.perf_counter()
    r = httpx.post(f"{svc.url}/v1/plans", json=finger_request(chain_urdf(joints)), timeout=300)
    took = time.perf_counter() - t0
    time.sleep(0.3)
    probe.stop.set()
    probe.join()
    return {"joints": joints, "bytes": len(chain_urdf(joints)), "status": r.status_code,
            "post_s": round(took, 3), "reason": r.text[:200], **probe.summary()}


def bench_deadlines(svc: Service, n: int) -> dict[str, Any]:
    base = json.loads((ROOT / "examples" / "three_finger_turn.json").read_text())
    ids = []
    for i in range(n):  # a new NLP structure each: its build counts
        req = {**base, "n_intervals": 30 + 2 * i, "solver": {"time_limit": 1.0}}
        r = httpx.post(f"{svc.url}/v1/plans", params={"wait": 0}, json=req, timeout=60)
        ids.append(r.json()["id"])
    jobs = []
    for job_id in ids:
        while True:
            job = httpx.get(f"{svc.url}/v1/plans/{job_id}", timeout=60).json()
            if job["state"] not in ("queued", "running"):
                jobs.append(job)
                break
            time.sleep(0.2)
    from datetime import datetime

    def ts(s: str) -> float:
        return datetime.fromisoformat(s).timestamp()

    late = [ts(j["finished_at"]) - ts(j["started_at"]) - 1.0 for j in jobs]
    codes = [j["code"] for j in jobs]
    return {"jobs": n, "late_median_s": round(statistics.median(late), 3),
            "late_max_s": round(max(late), 3),
            "killed": codes.count("killed_at_time_limit"),
            "with_plan": sum(1 for j in jobs if j["result"] and (
                j["result"].get("trajectory") or j["result"].get("grid"))),
            "codes": {c: codes.count(c) for c in sorted(set(codes))}}


def bench_results(svc: Service, gets: int) -> dict[str, Any]:
    req = json.loads((ROOT / "examples" / "triangle.json").read_text())
    req.update(n_intervals=2000, max_refinements=0, solver={"time_limit": 120.0},
               sample_times=[6.0 * i / 9999 for i in range(10000)])
    body = json.dumps(req)
    r = httpx.post(f"{svc.url}/v1/plans", params={"wait": 0}, content=body,
                   headers={"content-type": "application/json"}, timeout=60)
    job_id = r.json()["id"]
    while httpx.get(f"{svc.url}/v1/plans/{job_id}", timeout=60).json()["state"] in (
            "queued", "running"):
        time.sleep(0.5)
    size = len(httpx.get(f"{svc.url}/v1/plans/{job_id}", timeout=60).content)
    probe = Prober(svc)
    probe.start()
    time.sleep(0.3)
    t0 = time.perf_counter()
    with cf.ThreadPoolExecutor(gets) as pool:
        sizes = list(pool.map(lambda _: len(httpx.get(f"{svc.url}/v1/plans/{job_id}",
                                                      timeout=300).content), range(gets)))
    took = time.perf_counter() - t0
    time.sleep(0.3)
    probe.stop.set()
    probe.join()
    return {"request_bytes": len(body), "result_bytes": size, "gets": gets,
            "all_complete": all(s == size for s in sizes), "gets_s": round(took, 2),
            **probe.summary()}


def bench_clients(svc: Service, n: int, src: Path | None) -> dict[str, Any]:
    sys.path.insert(0, str((src or ROOT) / "clients" / "python"))  # that checkout's client
    from dexroll_client import DexrollClient

    req = json.loads((ROOT / "examples" / "triangle.json").read_text())
    errors: list[str] = []
    job_ids: list[str] = []
    lock = threading.Lock()

    def one(i: int) -> None:
        try:
            with DexrollClient.from_url(svc.url) as client:
                job = client.plan({**req, "duration": 6.0 + 0.001 * i}, timeout=600)
            with lock:
                job_ids.append(job.id)
        except Exception as exc:
            with lock:
                errors.append(f"{type(exc).__name__}: {exc}")

    with cf.ThreadPoolExecutor(n) as pool:
        list(pool.map(one, range(n)))
    listed = httpx.get(f"{svc.url}/v1/plans", params={"limit": 500}, timeout=60).json()
    return {"clients": n, "client_errors": len(errors), "errors": errors[:3],
            "jobs_in_store": listed["total"], "lost": n - len(set(job_ids)) - len(errors),
            "duplicated": listed["total"] - n}


def finished_roll(svc: Service) -> tuple[dict[str, Any], dict[str, Any], str]:
    """The one-finger roll (16 intervals) planned on the service: its request, its
    finished job and the job's simulation URL."""
    roll = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    roll["n_intervals"] = 16
    job = httpx.post(f"{svc.url}/v1/plans", params={"wait": 120}, json=roll,
                     timeout=300).json()
    assert job["state"] == "succeeded", job
    return roll, job, f"{svc.url}/v1/plans/{job['id']}/simulation"


def bench_simulations(svc: Service, n: int) -> dict[str, Any]:
    """``n`` concurrent long simulations of a one-finger plan (timestep 2e-5 s, settle
    2 s: about 200 000 steps each), every client leaving after 5 s, while GET /healthz,
    /readyz, /v1/plans, the job and /v1/models and a POST of a plan are timed in turn
    (issue 25: the API kept busy for about an hour by 45 of them)."""
    _, job, sim_url = finished_roll(svc)
    httpx.post(sim_url, json={}, timeout=300)  # the simulation process started
    codes: list[str] = []
    lock = threading.Lock()

    def simulate(_: int) -> None:
        try:
            r = httpx.post(sim_url, json={"timestep": 2e-5, "settle": 2.0}, timeout=5.0)
            code = str(r.status_code)
        except httpx.TimeoutException:
            code = "client_left"
        with lock:
            codes.append(code)

    paths = ["/healthz", "/readyz", "/v1/plans", f"/v1/plans/{job['id']}", "/v1/models"]
    triangle = json.loads((ROOT / "examples" / "triangle.json").read_text())

    def timed_rounds(until: Any) -> dict[str, list[float]]:
        """Every route timed in turn, round after round, until ``until()``."""
        latencies: dict[str, list[float]] = {p: [] for p in [*paths, "POST /v1/plans"]}
        with httpx.Client(timeout=60) as http:
            while not until():
                for path in paths:
                    t0 = time.perf_counter()
                    assert http.get(f"{svc.url}{path}").status_code == 200, path
                    latencies[path].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                http.post(f"{svc.url}/v1/plans", params={"wait": 0}, json=triangle)
                latencies["POST /v1/plans"].append(time.perf_counter() - t0)
                time.sleep(0.1)
        return latencies

    # the same rounds without simulations first, for 5 s: the machine's own noise; the
    # API process's CPU time and its threads' wait for a CPU (run queue) in each phase
    quiet_until = time.monotonic() + 5.0
    cpu0, wait0, t0 = *svc.cpu_and_wait_s(), time.perf_counter()
    quiet = timed_rounds(lambda: time.monotonic() > quiet_until)
    cpu1, wait1, t1 = *svc.cpu_and_wait_s(), time.perf_counter()
    load_before = os.getloadavg()[0]
    with cf.ThreadPoolExecutor(n) as pool:
        futures = [pool.submit(simulate, i) for i in range(n)]
        time.sleep(0.5)
        latencies = timed_rounds(lambda: all(f.done() for f in futures))
    cpu2, wait2, t2 = *svc.cpu_and_wait_s(), time.perf_counter()
    api = {"api_cpu_share_without": round((cpu1 - cpu0) / (t1 - t0), 3),
           "api_runqueue_wait_share_without": round((wait1 - wait0) / (t1 - t0), 3),
           "api_cpu_share_during": round((cpu2 - cpu1) / (t2 - t1), 3),
           "api_runqueue_wait_share_during": round((wait2 - wait1) / (t2 - t1), 3)}
    t0 = time.perf_counter()
    while httpx.get(f"{svc.url}/readyz", timeout=60).json()["simulations"]["running"]:
        time.sleep(0.1)
    idle_s = time.perf_counter() - t0
    def worst(lat: dict[str, list[float]]) -> float:
        return round(max(max(v) for v in lat.values() if v), 4)

    over = sum(x > 0.1 for v in latencies.values() for x in v)
    return {"simulations": n, "answers": {c: codes.count(c) for c in sorted(set(codes))},
            "pool_idle_after_clients_left_s": round(idle_s, 2),
            "load_average_1min": round(load_before, 2), **api,
            "worst_without_simulations_s": worst(quiet), "worst_during_s": worst(latencies),
            "answers_over_100ms_during": f"{over} of {sum(map(len, latencies.values()))}",
            "answers_over_100ms_without": f"{sum(x > 0.1 for v in quiet.values() for x in v)}"
                                          f" of {sum(map(len, quiet.values()))}",
            **{f"{p}_max_s": round(max(v), 4) for p, v in latencies.items() if v},
            **{f"{p}_median_s": round(statistics.median(v), 4)
               for p, v in latencies.items() if v}}


def bench_models(svc: Service, n: int) -> dict[str, Any]:
    """``n`` concurrent POSTs of a whole hand's URDF, each text distinct (a comment: every
    one checked by the model checker and loaded), while a plain POST (the triangle, no
    model, ``wait=0``) is timed in turn; the plain POST's latency alone first (issue 25:
    24 of them delayed it by 1.4-1.9 s)."""
    hand = json.loads((ROOT / "examples" / "hand_from_urdf.json").read_text())
    triangle = json.loads((ROOT / "examples" / "triangle.json").read_text())

    healthz: list[float] = []
    # a one-finger request with the built-in finger: no model either, but its checks use
    # the process's fingers (the cache a hand's load holds)
    finger = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    fingers: list[float] = []

    def plain_posts(http: httpx.Client, until: Any, at_least: int) -> list[float]:
        out: list[float] = []
        while len(out) < at_least or not until():
            t0 = time.perf_counter()
            r = http.post(f"{svc.url}/v1/plans", params={"wait": 0}, json=triangle)
            out.append(time.perf_counter() - t0)
            assert r.status_code in (201, 202, 503), r.text
            t0 = time.perf_counter()
            http.get(f"{svc.url}/healthz")
            healthz.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            r = http.post(f"{svc.url}/v1/plans", params={"wait": 0}, json=finger)
            fingers.append(time.perf_counter() - t0)
            assert r.status_code in (201, 202, 503), r.text
            time.sleep(0.05)
        return out

    with httpx.Client(timeout=300) as http:
        alone = plain_posts(http, lambda: True, 20)
    healthz.clear()
    fingers_alone = list(fingers)
    fingers.clear()
    codes: list[int] = []
    took: list[float] = []
    lock = threading.Lock()

    def post_hand(i: int) -> None:
        body = {**hand, "hand": {**hand["hand"],
                                 "urdf": hand["hand"]["urdf"] + f"<!-- variant {i} -->"},
                "solver": {"time_limit": 1.0}}
        t0 = time.perf_counter()
        r = httpx.post(f"{svc.url}/v1/plans", params={"wait": 0}, json=body, timeout=600)
        with lock:
            codes.append(r.status_code)
            took.append(time.perf_counter() - t0)

    with cf.ThreadPoolExecutor(n) as pool:
        futures = [pool.submit(post_hand, i) for i in range(n)]
        time.sleep(0.2)
        with httpx.Client(timeout=300) as http:
            loaded = plain_posts(http, lambda: all(f.done() for f in futures), 5)
    return {"hand_posts": n, "hand_answers": {c: codes.count(c) for c in sorted(set(codes))},
            "hand_post_median_s": round(statistics.median(took), 3),
            "hand_post_max_s": round(max(took), 3),
            "plain_post_alone_median_s": round(statistics.median(alone), 4),
            "plain_post_alone_max_s": round(max(alone), 4),
            "plain_posts_during": len(loaded),
            "plain_post_during_median_s": round(statistics.median(loaded), 4),
            "plain_post_during_p90_s": round(statistics.quantiles(loaded, n=10)[-1], 4),
            "plain_post_during_max_s": round(max(loaded), 4),
            "builtin_finger_post_alone_median_s": round(statistics.median(fingers_alone), 4),
            "builtin_finger_post_during_median_s": round(statistics.median(fingers), 4),
            "builtin_finger_post_during_max_s": round(max(fingers), 4),
            "healthz_during_median_s": round(statistics.median(healthz), 4),
            "healthz_during_max_s": round(max(healthz), 4)}


def bench_batch(svc: Service, n: int, sims: int) -> dict[str, Any]:
    """A batch of ``n`` plans (the ball rolled on the palm to ``n`` goals, every third
    one a finger rolling it: a mixed load) submitted as one, with ``sims`` concurrent
    long simulations of a finished plan (as :func:`bench_simulations`' clients, leaving
    after 5 s), while GET /healthz, /readyz, /v1/plans, a job and the batch are timed in
    turn until the batch is done (issue 39, item 4: the API's routes within 100 ms p99).
    Then: every job ended once (none lost, none duplicated), the NDJSON stream's lines."""
    roll, job, sim_url = finished_roll(svc)
    items = []
    for k in range(n):
        if k % 3 == 2:
            items.append({**roll, "duration": 1.5 + 0.01 * k})
        else:
            items.append({"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
                          "goal": {"x": 0.005 + 0.0001 * k}, "duration": 1.0,
                          "n_intervals": 10})

    def simulate(_: int) -> None:
        with contextlib.suppress(httpx.TimeoutException):
            httpx.post(sim_url, json={"timestep": 2e-5, "settle": 2.0}, timeout=5.0)

    t0 = time.perf_counter()
    r = httpx.post(f"{svc.url}/v1/batches", json={"items": items}, timeout=300)
    submit_s = time.perf_counter() - t0
    assert r.status_code == 201, r.text
    batch = r.json()
    paths = ["/healthz", "/readyz", "/v1/plans", f"/v1/plans/{job['id']}?result=false",
             f"/v1/batches/{batch['id']}"]
    latencies: dict[str, list[float]] = {p: [] for p in paths}
    started = time.perf_counter()
    with cf.ThreadPoolExecutor(max(sims, 1)) as pool, httpx.Client(timeout=60) as http:
        futures = [pool.submit(simulate, i) for i in range(sims)]
        done = False
        while not done:
            for path in paths:
                t0 = time.perf_counter()
                got = http.get(f"{svc.url}{path}")
                latencies[path].append(time.perf_counter() - t0)
                if path.startswith("/v1/batches"):
                    done = got.json()["done"]
            time.sleep(0.1)
        cf.wait(futures)
    batch_s = time.perf_counter() - started
    lines = httpx.get(f"{svc.url}/v1/batches/{batch['id']}/results",
                      params={"result": "false"}, timeout=300).text.splitlines()
    ids = [json.loads(x)["id"] for x in lines]
    final = httpx.get(f"{svc.url}/v1/batches/{batch['id']}", timeout=60).json()
    every = [x for v in latencies.values() for x in v]
    return {"plans": n, "simulations": sims, "submit_s": round(submit_s, 3),
            "batch_s": round(batch_s, 1), "plans_per_s": round(n / batch_s, 2),
            "counts": final["counts"], "lines": len(lines),
            "lost": n - len(set(ids)), "duplicated": len(ids) - len(set(ids)),
            "p99_all_ms": round(1e3 * float(np.percentile(every, 99)), 1),
            "over_100ms": f"{sum(x > 0.1 for x in every)} of {len(every)}",
            **{f"{p.split('?')[0]}_p99_ms": round(1e3 * float(np.percentile(v, 99)), 1)
               for p, v in latencies.items()},
            **{f"{p.split('?')[0]}_median_ms": round(1e3 * statistics.median(v), 1)
               for p, v in latencies.items()}}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("what", choices=["healthz", "deadlines", "results", "clients",
                                            "simulations", "models", "batch"])
    parser.add_argument("--sims", type=int, default=48)
    parser.add_argument("--src", type=Path)
    parser.add_argument("--joints", type=int, default=400)
    parser.add_argument("-n", type=int)
    args = parser.parse_args()
    # models: a queue the timed plain POSTs do not fill (the hand POSTs' 503s are then
    # the model checks' own)
    env = {"DEXROLL_MAX_QUEUE": "32"} if args.what == "clients" else \
        {"DEXROLL_MAX_QUEUE": "1000"} if args.what == "models" else {}
    svc = Service(args.src, **env)
    try:
        if args.what == "healthz":
            out = bench_healthz(svc, args.joints)
        elif args.what == "deadlines":
            out = bench_deadlines(svc, args.n or 20)
        elif args.what == "results":
            out = bench_results(svc, args.n or 40)
        elif args.what == "models":
            out = bench_models(svc, args.n or 24)
        elif args.what == "simulations":
            out = bench_simulations(svc, args.n or 40)
        elif args.what == "batch":
            out = bench_batch(svc, args.n or 200, args.sims)
        else:
            out = bench_clients(svc, args.n or 200, args.src)
    finally:
        svc.stop()
    print(json.dumps({"bench": args.what, "src": str(args.src or ROOT), **out}))


if __name__ == "__main__":
    main()
