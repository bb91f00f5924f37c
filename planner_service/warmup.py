"""Warm-up: build the NLPs of common problem structures before a worker takes jobs.

An NLP is built once per problem *structure* (planner, object shape, grid and via-point
segments, which coordinates the goals fix, the finger or hand, whether a motion is tracked)
and cached by the worker process; a request of a known structure pays only the solve. The
service's workers build the structures of the requests listed in ``DEXROLL_WARMUP`` (JSON
request files, or folders of them; by default the repository's ``examples/``) before they
report ready, so that the first such request does not pay for it.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from pathlib import Path

from pydantic import ValidationError

from dexroll_client.models import PlanRequest

from .planners import (
    REQUEST,
    BallOnPalmPlanner,
    FingerCache,
    Planners,
    ProblemError,
    adapter_for,
    request_errors,
)

__all__ = ["request_files", "warm", "warm_text", "warm_up"]

log = logging.getLogger("dexroll.warmup")


def request_files(spec: str) -> list[Path]:
    """The JSON request files named by ``spec``: comma-separated files or folders (a
    folder stands for its ``*.json``, sorted); missing paths are logged and skipped."""
    out: list[Path] = []
    for part in (p.strip() for p in spec.split(",")):
        if not part:
            continue
        path = Path(part)
        if path.is_dir():
            out += sorted(path.glob("*.json"))
        elif path.is_file():
            out.append(path)
        else:
            log.warning("warm-up: %s does not exist; skipped", path)
    return out


def warm(request: PlanRequest, palm: BallOnPalmPlanner, fingers: FingerCache) -> float:
    """Build the NLP of one request's structure in this process's planners (no solve).
    Returns the build time [s] (0 when it was cached already, or the planner builds
    none)."""
    return adapter_for(request).prepare(request, Planners(palm, fingers))


def warm_up(files: Iterable[Path], palm: BallOnPalmPlanner, fingers: FingerCache
            ) -> list[tuple[str, float]]:
    """Warm every valid request of ``files``; an invalid one is logged and skipped (a
    warm-up never stops a worker). Returns (file name, build time [s])."""
    done: list[tuple[str, float]] = []
    for path in files:
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            log.warning("warm-up: %s skipped: %s", path, exc)
            continue
        built = warm_text(path.name, text, palm, fingers)
        if built is not None:
            done.append((path.name, built))
    return done


def warm_text(name: str, text: str, palm: BallOnPalmPlanner, fingers: FingerCache
              ) -> float | None:
    """Warm the request of the JSON ``text`` (from the file ``name``): its build time
    [s], or None when it is not a valid request (logged: a warm-up never stops a worker).
    Workers on other machines (a Ray cluster) are sent the text, not the file's path."""
    try:
        request = REQUEST.validate_python(json.loads(text))
        errors = request_errors(request, fingers)
        if errors:
            log.warning("warm-up: %s is not a valid request (%s); skipped", name,
                        "; ".join(f"{f}: {r}" for f, r in errors))
            return None
        return warm(request, palm, fingers)
    except (ValueError, ValidationError, ProblemError) as exc:
        log.warning("warm-up: %s skipped: %s", name, exc)
        return None
