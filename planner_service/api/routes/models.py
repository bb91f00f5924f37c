"""``/v1/models``: what the service offers."""

from __future__ import annotations

from fastapi import APIRouter

from dexroll_client.models import ModelCatalog

from ...planners import FINGERS
from ...planners.catalog import model_catalog

__all__ = ["router"]

router = APIRouter()


@router.get("/v1/models", response_model=ModelCatalog)
def models() -> ModelCatalog:
    """Built-in objects, fingers (with their URDFs), hands and planners."""
    return model_catalog(FINGERS)
