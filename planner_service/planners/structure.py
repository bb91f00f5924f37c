"""A request's *structure key*: what decides which built NLPs it needs.

An NLP is built once per problem structure (planner, object shape, grid, the coordinates
the goals fix and the via-point segments, the finger or hand, a palm, a gait) and cached
by the process that built it; a request of a known structure pays only the solve. The key
is read off the request as sent (no model loaded, microseconds), so that the service's
dispatcher can route a job to a worker that holds its NLP and the bench can hand a unit
to the worker that built its structure: one function for both. It is an affinity, not an
identity: two requests with one key may still need different NLPs (the planners' own
caches decide), and a miss costs only a build.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

__all__ = ["structure_key"]


def _fingers(request: Mapping[str, Any]) -> list[Any]:
    out = []
    for f in request.get("fingers") or []:
        if isinstance(f, Mapping):
            out.append(f.get("finger") or f.get("hand_finger") or f.get("urdf"))
        else:
            out.append(f)
    return out


def structure_key(planner: str, request: Mapping[str, Any], method: str = "") -> str:
    """The structure key of ``request`` (a request's JSON object) to ``planner``; ``method``
    tells apart the bench's variants of one planner."""
    goal = sorted(request.get("goal") or {})
    vias = len(request.get("via_points") or [])
    obj = request.get("object") or {}
    shape = obj.get("shape", "sphere") if isinstance(obj, Mapping) else "sphere"
    if shape != "sphere" and isinstance(obj, Mapping) and isinstance(obj.get("dimensions"), list):
        shape = f"{shape}/{len(obj['dimensions'])}"  # an ellipsoid's 2 or 3: two surfaces
    n = request.get("n_intervals", 50)
    parts: list[Any]
    if planner == "manipulation":
        parts = ["manipulation", method, shape, n, request.get("hand"), _fingers(request),
                 request.get("palm") is not None, request.get("gait") is not None]
    elif planner == "one_finger":
        parts = ["one_finger", method, shape, n, goal, vias, request.get("finger")]
    else:
        parts = [planner, method, shape, n, goal, vias]
    text = json.dumps(parts, sort_keys=True, default=str)
    return f"{planner}:{hashlib.sha256(text.encode()).hexdigest()[:16]}"
