"""The service's throughput on local processes and on Ray actors, side by side (issue 39).

Each configuration starts a real `dexroll serve` (no warm-up: every structure is built by
its first plan on a worker) and submits the same batch of mixed plans: the README's
examples and the quick suite's ball, one-finger and two-finger families, cycled to ``-n``.
It reports per configuration: wall time and plans per second, the plans' own time on the
workers (median), the dispatch overhead per job (handing a job over and its verdict back,
less the worker's own time: the service's /readyz ``dispatch``), cache hits (the planners'
own ``stats.cache_hit``, and the rate after each worker's first plan of each structure),
and the service process's CPU time per job (the API and the dispatcher: what bounds a
cluster's throughput). Then a projection for a 64-core cluster, and a node lost mid-batch.

    python benchmarks/scale.py                  # local 2 | ray 1, 2, 4 actors; node lost
    python benchmarks/scale.py -n 60 --configs local:2 ray:2

Ray runs on a LocalRayCluster of this machine (``ray start`` on loopback): a head with as
many CPUs as actors (at equal CPUs with the local processes), and for the node loss a head
and a second node of one CPU each, the second killed when a third of the batch has ended.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from planner_service.bench.suite import expand, load_suite  # noqa: E402
from planner_service.executors.local_cluster import RAY_ENV, LocalRayCluster  # noqa: E402
from planner_service.planners.structure import structure_key  # noqa: E402

EXAMPLES = ["triangle.json", "reorient_horizontal_60deg.json",
            "reorient_vertical_90deg.json", "one_finger_roll.json",
            "experiment2_two_fingers.json"]
FAMILIES = ["translation", "reorientation", "full_goal", "one_finger", "two_fingers"]


def requests(n: int) -> list[dict[str, Any]]:
    """``n`` mixed plan requests: the examples and the families' problems, cycled."""
    pool = [json.loads((ROOT / "examples" / name).read_text()) for name in EXAMPLES]
    pool += [dict(p.request) for p in expand(load_suite("quick"), FAMILIES)]
    return [pool[i % len(pool)] for i in range(n)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Service:
    def __init__(self, workers: int, env: dict[str, str]) -> None:
        self.data = Path(tempfile.mkdtemp(prefix="dexroll-scale-"))
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        environ = {**os.environ, "DEXROLL_PORT": str(self.port), "DEXROLL_DATA_DIR":
                   str(self.data), "DEXROLL_WORKERS": str(workers), "DEXROLL_WARMUP": "",
                   "DEXROLL_MAX_QUEUE": "10000", "DEXROLL_LOG_LEVEL": "warning", **env}
        self.log = (self.data / "service.log").open("wb")
        self.proc = subprocess.Popen([sys.executable, "-m", "planner_service.cli", "serve"],
                                     env=environ, stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 300
        while True:
            try:
                ready = httpx.get(f"{self.url}/readyz", timeout=5)
                if ready.status_code == 200 and ready.json()["workers"] >= min(workers, 2):
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise RuntimeError((self.data / "service.log").read_text()[-3000:])
            time.sleep(0.3)
        # every worker up (a Ray actor beyond the cluster's CPUs would wait for one)
        wait_until = time.monotonic() + 60
        while httpx.get(f"{self.url}/readyz").json()["workers"] < workers and \
                time.monotonic() < wait_until:
            time.sleep(0.3)

    def cpu(self) -> float:
        """CPU seconds of the service process (API and dispatcher threads)."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()
        shutil.rmtree(self.data, ignore_errors=True)


def run_batch(service: Service, items: list[dict[str, Any]], on_progress: Any = None,
              cluster: LocalRayCluster | None = None) -> dict[str, Any]:
    daemons0 = cluster.daemon_cpu() if cluster is not None else 0.0
    cpu0, t0 = service.cpu(), time.perf_counter()
    r = httpx.post(f"{service.url}/v1/batches", json={"items": items}, timeout=120)
    r.raise_for_status()
    batch_id = r.json()["id"]
    item_of = dict(zip(r.json()["job_ids"], items, strict=True))
    if on_progress is not None:
        threading.Thread(target=on_progress, args=(batch_id,), daemon=True).start()
    lines = httpx.get(f"{service.url}/v1/batches/{batch_id}/results",
                      params={"order": "finished"}, timeout=3600).text.splitlines()
    wall = time.perf_counter() - t0
    cpu = service.cpu() - cpu0
    daemons = cluster.daemon_cpu() - daemons0 if cluster is not None else None
    jobs = [json.loads(line) for line in lines]
    ready = httpx.get(f"{service.url}/readyz").json()
    firsts: set[tuple[str, int]] = set()
    hits = after = 0
    own = []
    for job in sorted(jobs, key=lambda j: j.get("finished_at") or ""):
        stats = (job.get("result") or {}).get("stats") or {}
        hits += bool(stats.get("cache_hit", stats.get("build_time", 1.0) == 0.0))
        if job.get("started_at") and job.get("finished_at"):
            own.append((datetime.fromisoformat(job["finished_at"])
                        - datetime.fromisoformat(job["started_at"])).total_seconds())
        request = item_of.get(job["id"], {})
        key = (structure_key(str(request.get("planner", "ball_on_palm")), request),
               int(job.get("worker_pid") or 0))
        after += key in firsts
        firsts.add(key)
    states: dict[str, int] = {}
    for job in jobs:
        states[job["state"]] = states.get(job["state"], 0) + 1
    return {"plans": len(jobs), "distinct_ids": len({j["id"] for j in jobs}),
            "states": states, "wall_s": round(wall, 2),
            "plans_per_s": round(len(jobs) / wall, 3),
            "job_time_median_s": round(statistics.median(own), 3) if own else None,
            "cache_hits": ready["cache"]["hits"], "cache_misses": ready["cache"]["misses"],
            "hits": hits, "repeats_on_a_worker": after,
            "dispatch": ready.get("dispatch"), "service_cpu_per_job_ms":
            round(1e3 * cpu / max(1, len(jobs)), 2), "requeued": ready.get("requeued"),
            "ray_daemons_cpu_s": None if daemons is None else round(daemons, 2)}


def configuration(kind: str, actors: int, items: list[dict[str, Any]]) -> dict[str, Any]:
    cluster = None
    env: dict[str, str] = {}
    try:
        if kind == "ray":
            cluster = LocalRayCluster(head_cpus=actors, node_cpus=())
            env = {**RAY_ENV, "DEXROLL_EXECUTOR": "ray", "DEXROLL_RAY_ADDRESS":
                   cluster.address}
        service = Service(actors, env)
        try:
            return {"executor": kind, "workers": actors,
                    **run_batch(service, items, cluster=cluster)}
        finally:
            service.stop()
    finally:
        if cluster is not None:
            cluster.stop()


def node_lost(items: list[dict[str, Any]]) -> dict[str, Any]:
    cluster = LocalRayCluster(head_cpus=1, node_cpus=(1,))
    killed: dict[str, Any] = {}
    try:
        service = Service(2, {**RAY_ENV, "DEXROLL_EXECUTOR": "ray",
                              "DEXROLL_RAY_ADDRESS": cluster.address})

        def kill_when_a_third_ended(batch_id: str) -> None:
            while True:
                counts = httpx.get(f"{service.url}/v1/batches/{batch_id}").json()["counts"]
                ended = sum(v for k, v in counts.items() if k not in ("queued", "running"))
                if ended >= len(items) // 3:
                    cluster.kill_node("node1")
                    killed.update(at_ended=ended, counts=counts)
                    return
                time.sleep(0.2)

        try:
            out = run_batch(service, items, kill_when_a_third_ended, cluster)
        finally:
            service.stop()
        return {"executor": "ray", "workers": 2, "node_killed": killed, **out,
                "lost": len(items) - out["distinct_ids"],
                "duplicated": out["plans"] - out["distinct_ids"]}
    finally:
        cluster.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-n", type=int, default=200, help="plans per configuration")
    parser.add_argument("--configs", nargs="*",
                        default=["local:1", "ray:1", "local:2", "ray:2", "ray:4"],
                        help="executor:workers, run in this order")
    parser.add_argument("--repeats", type=int, default=1,
                        help="runs of every configuration, interleaved (the summary gives "
                             "their median plans per second)")
    parser.add_argument("--no-node-loss", action="store_true")
    args = parser.parse_args()
    items = requests(args.n)
    rows = []
    runs: dict[str, list[float]] = {}
    for _ in range(args.repeats):
        for spec in args.configs:
            kind, workers = spec.split(":")
            row = configuration(kind, int(workers), items)
            rows.append(row)
            runs.setdefault(spec, []).append(row["plans_per_s"])
            print(json.dumps(row), flush=True)
    print(json.dumps({"median_plans_per_s": {k: statistics.median(v) for k, v in runs.items()},
                      "runs": runs}), flush=True)
    one = next((r for r in rows if r["workers"] == 1), None)
    if one is not None:  # one worker builds each structure once: their number
        structures = one["cache_misses"]
        for row in rows:
            repeats = row["plans"] - structures
            print(json.dumps({"executor": row["executor"], "workers": row["workers"],
                              "structures": structures, "builds": row["cache_misses"],
                              "hit_rate_after_first_of_each_structure":
                              round(row["cache_hits"] / repeats, 3) if repeats else None}),
                  flush=True)
    ray2 = next((r for r in rows if r["executor"] == "ray" and r["workers"] == 2), None)
    if ray2 is not None and ray2["job_time_median_s"]:
        per_plan = ray2["job_time_median_s"]
        dispatch = (ray2["dispatch"] or {}).get("median_ms", 0.0) / 1e3
        ceiling = 1e3 / max(ray2["service_cpu_per_job_ms"], 1e-3)
        print(json.dumps({"projection": "64 actors", "per_plan_s": per_plan,
                          "dispatch_s": round(dispatch, 4),
                          "plans_per_s_by_workers": round(64 / (per_plan + dispatch), 1),
                          "plans_per_s_service_ceiling": round(ceiling, 1)}), flush=True)
    if not args.no_node_loss:
        print(json.dumps({"node_lost": node_lost(items)}), flush=True)


if __name__ == "__main__":
    main()
