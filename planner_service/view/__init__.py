"""The plan viewer: an animated 3D view of a plan in the browser (docs/viewer.md).

:func:`view_html` turns a plan's wire result (and, when at hand, its request) into one
self-contained HTML page: the palm, the object turning and rolling, the fingers' links from
their own models, the pads, the contact points and their traces, the friction cones, and a
timeline. The service serves it at ``GET /v1/plans/{id}/view``; ``dexroll view
RESULT.json -o plan.html`` writes it to a file.

* :mod:`.tracks`: the plan's arrays in one shape, whatever its planner;
* :mod:`.models`: the object, palm and fingers to draw it with (the request's, or inferred);
* :mod:`.robot`: a finger's link shapes and their poses, by Pinocchio;
* :mod:`.scene`: every pose at every sample, as JSON for the page;
* :mod:`.page`: the HTML (three.js and ``static/viewer.js`` inlined).
"""

from __future__ import annotations

from typing import Any

from dexroll_client.models import AnyPlanResult, PlanRequest

from ..plans import read_result
from ..plans.models import SceneModels, infer_models, models_from_request
from ..plans.tracks import NoPlanError, PlanTracks, has_plan, tracks_of
from .page import THREE_VERSION, page_html
from .scene import build_scene

__all__ = [
    "THREE_VERSION",
    "NoPlanError",
    "PlanTracks",
    "SceneModels",
    "build_scene",
    "has_plan",
    "page_html",
    "page_of_job",
    "read_result",
    "scene_of",
    "tracks_of",
    "view_html",
]


def scene_of(result: AnyPlanResult, request: PlanRequest | None = None, title: str = ""
             ) -> dict[str, Any]:
    """The scene of a plan (:func:`~.scene.build_scene`), drawn with its request's object
    and fingers when ``request`` is given, inferred from the result otherwise.
    :class:`NoPlanError` when the result holds no plan."""
    tracks = tracks_of(result)
    models = infer_models(tracks) if request is None else models_from_request(request, tracks)
    gait = getattr(result, "gait", None)
    phases = None if gait is None or not gait.phases else [
        {"kind": p.kind, "start": p.start, "end": p.end, "lifted": p.lifted_finger}
        for p in gait.phases]
    return build_scene(tracks, models, title, phases)


def view_html(result: AnyPlanResult, request: PlanRequest | None = None, title: str = ""
              ) -> str:
    """The standalone page of a plan (see :func:`scene_of`)."""
    return page_html(scene_of(result, request, title))


def page_of_job(result_json: str, request_json: str, title: str) -> str:
    """The page of a stored job (its result's and its request's JSON): what the service's
    viewer runs in a model checker's process, under its time and memory limits
    (:meth:`~planner_service.models_check.ModelChecker.call`): the request's finger
    models are loaded here."""
    from ..planners import REQUEST, RESULT

    return view_html(RESULT.validate_json(result_json), REQUEST.validate_json(request_json),
                     title)
