"""A finished plan read back for what shows it or runs it: its tracks on the wire's
samples (:mod:`.tracks`), the models it moves (:mod:`.models`: the object, the fingers and
hands of its request), their shapes (:mod:`.shapes`) and a result file. Shared by the viewer
(:mod:`planner_service.view`) and the execution in MuJoCo (:mod:`planner_service.execution`),
which import neither each other nor the core's internals."""

from __future__ import annotations

import json
from pathlib import Path

from dexroll_client.models import AnyPlanResult

__all__ = ["read_result"]


def read_result(path: Path) -> tuple[AnyPlanResult, str | None]:
    """A plan's result from a file: a result as ``dexroll plan`` writes it, or a job as
    ``GET /v1/plans/{id}`` answers it (its ``result``); and the job's id (None for a
    result file). ValueError saying why the file is neither."""
    from ..planners import RESULT

    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"cannot read {path}: {exc}") from exc
    job_id = None
    if isinstance(raw, dict) and "result" in raw and "state" in raw:
        job_id = str(raw.get("id")) if raw.get("id") is not None else None
        raw = raw["result"]
        if raw is None:
            raise ValueError(f"{path} is a job without a result (not finished?)")
    try:
        return RESULT.validate_python(raw), job_id
    except Exception as exc:
        raise ValueError(f"{path} is not a plan result: {exc}") from exc
