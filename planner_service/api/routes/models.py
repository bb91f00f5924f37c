"""``/v1/models``: what the service offers."""

from __future__ import annotations

import threading

from fastapi import APIRouter, Response

from dexroll_client.models import ModelCatalog

from ...planners import FINGERS
from ...planners.catalog import model_catalog

__all__ = ["router"]

router = APIRouter()

#: The catalog's JSON, built once per process (built-in models only: it never changes;
#: building it poses the hands' nominal grasps, tens of milliseconds of the interpreter).
_catalog: list[bytes] = []
_lock = threading.Lock()


@router.get("/v1/models", response_model=ModelCatalog)
def models() -> Response:
    """Built-in objects, fingers (with their URDFs), hands and planners."""
    with _lock:
        if not _catalog:
            _catalog.append(model_catalog(FINGERS).model_dump_json().encode())
    return Response(_catalog[0], media_type="application/json")
