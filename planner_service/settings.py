"""Service configuration from environment variables (prefix ``DEXROLL_``), pydantic-settings.

| variable | default | meaning |
|---|---|---|
| DEXROLL_HOST | 127.0.0.1 | address to listen on |
| DEXROLL_PORT | 8000 | port |
| DEXROLL_DATA_DIR | ./data | folder of the SQLite job store (created) |
| DEXROLL_WORKERS | CPU count | solver workers (processes, or Ray actors) |
| DEXROLL_EXECUTOR | local | where workers run: `local` processes or `ray` actors |
| DEXROLL_RAY_ADDRESS | auto | the Ray cluster of the `ray` executor (`ray start`'s address) |
| DEXROLL_RETRIES | 1 | times a job is queued again when its worker is lost under it |
| DEXROLL_MAX_TIME_LIMIT | 120 | cap on a request's solver.time_limit [s] |
| DEXROLL_KILL_GRACE | 5 | extra time before a worker past its time limit is killed [s] |
| DEXROLL_MAX_QUEUE | 64 | queued jobs accepted before POST answers 503 |
| DEXROLL_MAX_BODY_BYTES | 1048576 | request bodies above this get 413 |
| DEXROLL_DEFAULT_WAIT | 1.0 | how long POST waits for a plan by default [s] |
| DEXROLL_MAX_WAIT | 30 | cap on POST's ?wait= [s] |
| DEXROLL_LOG_LEVEL | info | log level |
| DEXROLL_WARMUP | examples | requests whose NLPs a worker builds between jobs |
| DEXROLL_WARMUP_FIRST | false | build them before a worker reports ready (else: once imported) |
| DEXROLL_COMPILE_DIR | (none) | compile NLPs to C libraries cached here |
| DEXROLL_MODEL_MAX_BYTES | 500000 | characters of a model (URDF) text in a request |
| DEXROLL_MODEL_MAX_JOINTS | 64 | joints of a model's XML tree (every kind) |
| DEXROLL_MODEL_MAX_LINKS | 128 | links (MJCF: bodies) of a model's XML tree |
| DEXROLL_MODEL_MAX_DEPTH | 32 | joints on the longest chain of a model's tree |
| DEXROLL_MODEL_CHECK_SECONDS | 5 | time a model may take to parse and load [s] |
| DEXROLL_MODEL_CHECK_MEMORY_MB | 512 | memory a model may take to load [MB] |
| DEXROLL_MODEL_CHECKERS | 1 | processes that check models from requests |
| DEXROLL_RETENTION_DAYS | 30 | finished jobs older than this are purged (0: never) |
| DEXROLL_MAX_JOBS | 10000 | beyond this many jobs the oldest finished ones are purged |
| DEXROLL_MAX_RESULT_BYTES | 67108864 | a plan's JSON above this is not stored (job failed) |
| DEXROLL_SIM_PROCESSES | 1 | processes that run simulations (never the API's own) |
| DEXROLL_SIM_QUEUE | 4 | simulations waiting before POST .../simulation answers 503 |
| DEXROLL_SIM_TIME_LIMIT | 120 | wall time of one simulation before it is stopped [s] |
| DEXROLL_SIM_CPU_SECONDS | 120 | CPU time of one simulation before it is stopped [s] |
| DEXROLL_SIM_MAX_STEPS | 500000 | physics steps one simulation may ask for (else 422) |
| DEXROLL_REPLAN_PROCESSES | 1 | processes that answer POST .../replan (never a worker's) |
| DEXROLL_REPLAN_CACHE | 8 | plans whose re-planner each re-plan process keeps |
| DEXROLL_REPLAN_QUEUE | 8 | re-plans waiting before POST .../replan answers 503 |
| DEXROLL_REPLAN_TIME_LIMIT | 10 | cap on a re-plan's own time_limit [s] |
| DEXROLL_REPLAN_SETUP_LIMIT | 300 | a plan's first re-plan: building its re-planner [s] |
| DEXROLL_API_KEYS | (none) | `owner:key` pairs (or bare keys), comma-separated |
| DEXROLL_API_KEYS_FILE | (none) | a file of `owner:key` lines, read at start |
| DEXROLL_ALLOWED_HOSTS | 127.0.0.1,localhost,::1 | Host headers served (`*`: any) |

``DEXROLL_COMPILE_DIR``: when set, each finger structure's NLP functions are generated as
C, compiled with gcc and kept there as shared libraries that every worker and later service
loads (``ocp.solve.compiled``): a few seconds of gcc per structure the first time, in a
background thread of the worker while the virtual machine solves its requests; the
compiled solver takes over from the first request after the compile (IPOPT ~40 % faster on
experiment 1). Without gcc the workers go on with the virtual machine. Ball-on-palm NLPs
are not compiled by the service.

``DEXROLL_WARMUP``: comma-separated JSON request files or folders (relative to the working
directory; missing ones are skipped, see ``planner_service.warmup``); empty: none.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from .models_check import ModelLimits

__all__ = ["Settings"]


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="DEXROLL_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    data_dir: Path = Path("data")
    workers: int = Field(default_factory=lambda: max(1, os.cpu_count() or 1), ge=1, le=256)
    #: where the solver workers run (planner_service.executors): "local" or "ray"
    executor: Literal["local", "ray"] = "local"
    ray_address: str = "auto"
    retries: int = Field(default=1, ge=0, le=10)
    max_time_limit: float = Field(default=120.0, gt=0.0, le=3600.0)
    kill_grace: float = Field(default=5.0, ge=0.0, le=600.0)
    max_queue: int = Field(default=64, ge=1, le=100_000)
    max_body_bytes: int = Field(default=1 << 20, ge=1024)
    default_wait: float = Field(default=1.0, ge=0.0, le=600.0)
    max_wait: float = Field(default=30.0, ge=0.0, le=600.0)
    log_level: str = "info"
    warmup: str = "examples"
    #: build the warm-up NLPs before a worker reports ready; by default a worker is ready
    #: once it has imported the planners (seconds) and builds them one at a time while no
    #: job waits (measured 2026-12-05: a service under load waited over 60 s to be ready)
    warmup_first: bool = False
    compile_dir: Path | None = None
    # model files from requests, checked in isolated processes (planner_service.models_check)
    model_max_bytes: int = Field(default=500_000, ge=1_000, le=50_000_000)
    model_max_joints: int = Field(default=64, ge=1, le=10_000)
    model_max_links: int = Field(default=128, ge=1, le=10_000)
    model_max_depth: int = Field(default=32, ge=1, le=10_000)
    model_check_seconds: float = Field(default=5.0, gt=0.0, le=600.0)
    model_check_memory_mb: int = Field(default=512, ge=64, le=1 << 20)
    model_checkers: int = Field(default=1, ge=1, le=64)
    # retention (planner_service.jobs.store.Store.purge) and the size of a stored plan
    retention_days: float = Field(default=30.0, ge=0.0, le=36_500.0)
    max_jobs: int = Field(default=10_000, ge=1, le=100_000_000)
    max_result_bytes: int = Field(default=64 << 20, ge=1 << 16)
    # simulations (planner_service.jobs.simulations)
    sim_processes: int = Field(default=1, ge=1, le=64)
    sim_queue: int = Field(default=4, ge=0, le=10_000)
    sim_time_limit: float = Field(default=120.0, gt=0.0, le=86_400.0)
    sim_cpu_seconds: float = Field(default=120.0, gt=0.0, le=86_400.0)
    sim_max_steps: int = Field(default=500_000, ge=1_000, le=1_000_000_000)
    # re-plans from a measured state (planner_service.jobs.replans)
    replan_processes: int = Field(default=1, ge=1, le=64)
    replan_cache: int = Field(default=8, ge=1, le=1_000)
    replan_queue: int = Field(default=8, ge=0, le=10_000)
    replan_time_limit: float = Field(default=10.0, gt=0.0, le=600.0)
    replan_setup_limit: float = Field(default=300.0, gt=0.0, le=86_400.0)
    # who may use the service (planner_service.api.access)
    api_keys: str = ""
    api_keys_file: Path | None = None
    allowed_hosts: str = "127.0.0.1,localhost,::1"

    def model_limits(self) -> ModelLimits:
        """The limits of a model text from a request."""
        return ModelLimits(max_bytes=self.model_max_bytes, max_joints=self.model_max_joints,
                           max_links=self.model_max_links,
                           max_chain_depth=self.model_max_depth,
                           time_limit=self.model_check_seconds,
                           memory_bytes=self.model_check_memory_mb << 20)

    def keys(self) -> dict[str, str]:
        """The API keys: key -> owner (empty: no keys, every request is the one local
        user's). ``owner:key`` pairs (a key has no ``:`` and at least 16 characters); a bare
        key's owner is named by a hash of it."""
        entries = [e for e in self.api_keys.split(",") if e.strip()]
        if self.api_keys_file is not None:
            entries += [line for line in self.api_keys_file.read_text().splitlines()
                        if line.strip() and not line.lstrip().startswith("#")]
        out: dict[str, str] = {}
        for entry in entries:
            owner, sep, key = entry.strip().rpartition(":")
            if not sep:
                owner = "key-" + hashlib.sha256(key.encode()).hexdigest()[:12]
            if len(key) < 16:
                raise ValueError("an API key must have at least 16 characters")
            out[key] = owner.strip() or "key-" + hashlib.sha256(key.encode()).hexdigest()[:12]
        return out

    def hosts(self) -> list[str]:
        """The Host names served (lower case, without port); ['*']: any."""
        return [h.strip().lower() for h in self.allowed_hosts.split(",") if h.strip()]

    @property
    def db_path(self) -> Path:
        return self.data_dir / "jobs.sqlite3"
