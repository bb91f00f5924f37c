"""Service configuration from environment variables (prefix ``DEXROLL_``), pydantic-settings.

| variable | default | meaning |
|---|---|---|
| DEXROLL_HOST | 127.0.0.1 | address to listen on |
| DEXROLL_PORT | 8000 | port |
| DEXROLL_DATA_DIR | ./data | folder of the SQLite job store (created) |
| DEXROLL_WORKERS | CPU count | solver worker processes |
| DEXROLL_MAX_TIME_LIMIT | 120 | cap on a request's solver.time_limit [s] |
| DEXROLL_KILL_GRACE | 5 | extra time before a worker past its time limit is killed [s] |
| DEXROLL_MAX_QUEUE | 64 | queued jobs accepted before POST answers 503 |
| DEXROLL_MAX_BODY_BYTES | 1048576 | request bodies above this get 413 |
| DEXROLL_DEFAULT_WAIT | 1.0 | how long POST waits for a plan by default [s] |
| DEXROLL_MAX_WAIT | 30 | cap on POST's ?wait= [s] |
| DEXROLL_LOG_LEVEL | info | log level |
| DEXROLL_WARMUP | examples | requests whose NLPs a worker builds before it is ready |
| DEXROLL_COMPILE_DIR | (none) | compile NLPs to C libraries cached here |

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

import os
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings"]


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="DEXROLL_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    data_dir: Path = Path("data")
    workers: int = Field(default_factory=lambda: max(1, os.cpu_count() or 1), ge=1, le=256)
    max_time_limit: float = Field(default=120.0, gt=0.0, le=3600.0)
    kill_grace: float = Field(default=5.0, ge=0.0, le=600.0)
    max_queue: int = Field(default=64, ge=1, le=100_000)
    max_body_bytes: int = Field(default=1 << 20, ge=1024)
    default_wait: float = Field(default=1.0, ge=0.0, le=600.0)
    max_wait: float = Field(default=30.0, ge=0.0, le=600.0)
    log_level: str = "info"
    warmup: str = "examples"
    compile_dir: Path | None = None

    @property
    def db_path(self) -> Path:
        return self.data_dir / "jobs.sqlite3"
