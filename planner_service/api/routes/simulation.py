"""``/v1/plans/{id}/simulation``: a finished job's plan executed in MuJoCo, its report
stored beside the plan (docs/simulation.md).

``POST`` runs the simulation in the service's simulation pool
(:class:`~planner_service.jobs.simulations.SimulationPool`: processes of its own, never the
API's) and answers 201 with the report, which it stores as the job's latest; ``GET``
answers the stored report. A job without a plan a hand executes (still running, failed
without a plan, a ball-on-palm plan, a plan too long to simulate here) is a 409; options
asking for more than ``DEXROLL_SIM_MAX_STEPS`` physics steps a 422 naming ``timestep``;
a full simulation queue, a run past its time or CPU budget, or a service installed without
MuJoCo (the ``sim`` extra) a 503. A run whose client has left is stopped.
"""

from __future__ import annotations

import asyncio
import importlib.util
import math
import threading
from collections import OrderedDict
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response

from dexroll_client.models import ErrorBody, FieldError
from dexroll_client.simulation import SimulationOptions, SimulationReport

from ...jobs.simulations import SimulationPool, SimulationRefusedError
from ...planners import RESULT
from ...plans.tracks import tracks_of
from ...view import NoPlanError
from ..access import OwnerDep
from ..body import JSONBodyRoute
from ..deps import ServiceError, SettingsDep, StoreDep, finished_job

__all__ = ["router", "simulation_steps"]

router = APIRouter(route_class=JSONBodyRoute)

#: The longest plan simulated here [s]; a longer one: ``dexroll simulate`` on its result.
MAX_SIMULATED_DURATION = 120.0
#: The simulator's defaults of the options that set the step count (sim.SimOptions).
DEFAULT_TIMESTEP, DEFAULT_SETTLE = 5e-4, 0.2
#: How often a waiting POST looks whether its client is still there [s].
_DISCONNECT_POLL = 0.25

_RESPONSES: dict[int | str, dict[str, Any]] = {
    409: {"model": ErrorBody,
          "description": "the job has not finished, or has no plan a hand executes"},
    422: {"model": ErrorBody,
          "description": "an invalid option, or options asking for more physics steps "
                         "than the service simulates (`timestep` named, with the limit)"},
    503: {"model": ErrorBody,
          "description": "the simulation queue is full (Retry-After), the run went past "
                         "its time or CPU budget, or this service was installed without "
                         "MuJoCo (the `sim` extra)"},
}


def _path(job_id: str) -> str:
    return f"/v1/plans/{job_id}/simulation"


def simulation_steps(duration: float, options: SimulationOptions) -> int:
    """The physics steps of a run of a plan of ``duration`` [s] with ``options``: the
    settling's and the plan's (as ``sim.run`` counts them)."""
    dt = options.timestep if options.timestep is not None else DEFAULT_TIMESTEP
    settle = options.settle if options.settle is not None else DEFAULT_SETTLE
    return round(settle / dt) + math.ceil(duration / dt - 1e-9)


#: Plan horizons (or why a plan has none to execute) by job id and end time: a flood of
#: simulations of one plan parses its result once (a parse holds the interpreter for tens
#: of milliseconds, which every other route of the API process waits for).
_durations: OrderedDict[tuple[str, float | None], float | ServiceError] = OrderedDict()
_durations_lock = threading.Lock()
_CACHED_DURATIONS = 64


def _cached_plan_duration(job_id: str, finished_at: float | None, result_json: str) -> float:
    """:func:`_plan_duration`, computed once per finished job (the others asking for it
    meanwhile wait for that one)."""
    key = (job_id, finished_at)
    with _durations_lock:
        value = _durations.get(key)
        if value is None:
            try:
                value = _plan_duration(job_id, result_json)
            except ServiceError as exc:
                value = exc
            _durations[key] = value
            while len(_durations) > _CACHED_DURATIONS:
                _durations.popitem(last=False)
    if isinstance(value, ServiceError):  # a fresh error each time (its own traceback)
        raise ServiceError(value.status, value.error, value.message, value.detail,
                           value.headers)
    return value


def _plan_duration(job_id: str, result_json: str) -> float:
    """The plan's horizon [s] (409 when it has nothing a hand executes)."""
    try:
        tracks = tracks_of(RESULT.validate_json(result_json))
    except NoPlanError as exc:
        raise ServiceError(409, "not_executable", f"job {job_id}: {exc}") from exc
    if not tracks.fingers:
        raise ServiceError(409, "not_executable", f"job {job_id}: a {tracks.planner} plan "
                                                  "has no fingers: nothing for a hand to "
                                                  "execute")
    return float(tracks.t[-1] - tracks.t[0])


async def _outcome(request: Request, pool: SimulationPool, result_json: str,
                   request_json: str, options: dict[str, Any]) -> dict[str, Any]:
    """The run's report; it is stopped when the client leaves before it ends."""
    try:
        task = pool.submit(result_json, request_json, options)
    except SimulationRefusedError as exc:
        raise _refused(exc) from exc
    waiting = asyncio.wrap_future(task.future)
    try:
        while True:
            done, _ = await asyncio.wait({waiting}, timeout=_DISCONNECT_POLL)
            if done:
                break
            if await request.is_disconnected():
                pool.cancel(task)
                raise ServiceError(499, "cancelled", "the client left")
    finally:
        if not waiting.done():  # the client left (or the service stops): nobody waits
            pool.cancel(task)
            waiting.cancel()
    try:
        return waiting.result()
    except SimulationRefusedError as exc:
        raise _refused(exc) from exc


def _loop_errors(options: SimulationOptions, duration: float) -> list[tuple[str, str]]:
    """What the disturbances and the closed loop cannot do with these options and a plan
    of ``duration`` [s], fields named."""
    errors: list[tuple[str, str]] = []
    d = options.disturbances
    if (d is not None or options.closed_loop is not None) and options.model == "request":
        errors.append(("model", "disturbances and the closed loop run on dexroll's own "
                                "scene only, not yet on the request's hand model"))
    if options.closed_loop is not None and options.mode != "servo":
        errors.append(("mode", "the closed loop drives the joints through their servos: "
                               "mode 'servo'"))
    if d is not None:
        for name in ("pushes", "impulses"):
            for i, k in enumerate(getattr(d, name)):
                if k.time > duration:
                    errors.append((f"disturbances.{name}[{i}].time",
                                   f"{k.time:g} s is after the plan's end ({duration:g} s)"))
    return errors


def _refused(exc: SimulationRefusedError) -> ServiceError:
    headers = None if exc.retry_after is None else {"Retry-After": str(exc.retry_after)}
    return ServiceError(exc.status, exc.error, exc.message, headers=headers)


@router.post("/v1/plans/{job_id}/simulation", status_code=201,
             response_model=SimulationReport, responses=_RESPONSES)
async def simulate_plan(job_id: str, request: Request, store: StoreDep, owner: OwnerDep,
                        settings: SettingsDep,
                        options: SimulationOptions | None = None) -> Response:
    """Execute a finished job's plan in MuJoCo with the plan's own hand, object and
    friction: the fingers' joints follow the plan through position servos (or are set to
    it: `mode`), with a grip (`squeeze`, `grip_force`; a plan's own forces when it has
    them). The report (the object's position and orientation errors over time, every
    contact's losses, slip and normal force, pass or fail against `tolerances`) is stored
    as the job's latest (`GET` answers it). The run happens in the service's simulation
    processes, at most `DEXROLL_SIM_MAX_STEPS` physics steps ((settle + the plan's
    duration) / timestep), stopped past its time or CPU budget or when the client
    leaves. `disturbances` disturb the run (pushes, impulses, friction, size, mass, pose
    noise); `closed_loop` re-plans from the measured state at its rate while it runs and
    runs the open loop in the same world beside it: the report is the closed loop's, with
    `open_loop` and `closed_loop` (each one's summary against the task's goal: `recovered`;
    the controller's calls and timing) as `dexroll simulate --closed-loop` writes them."""
    row = finished_job(await asyncio.to_thread(store.get, job_id, owner), job_id,
                       "it can be simulated")
    assert row.result is not None  # finished_job's no_plan
    options = options or SimulationOptions()
    if importlib.util.find_spec("mujoco") is None:
        raise ServiceError(503, "simulation_unavailable",
                           "this service was installed without MuJoCo: pip install "
                           "'dexroll[sim]'")
    duration = await asyncio.to_thread(_cached_plan_duration, job_id, row.finished_at,
                                       row.result)
    if duration > MAX_SIMULATED_DURATION:
        raise ServiceError(409, "too_long", f"job {job_id}: a plan of {duration:g} s "
                                            f"is longer than the "
                                            f"{MAX_SIMULATED_DURATION:g} s this service "
                                            "simulates: run `dexroll simulate` on its "
                                            "result")
    steps, limit = simulation_steps(duration, options), settings.sim_max_steps
    if steps > limit:
        settle = options.settle if options.settle is not None else DEFAULT_SETTLE
        smallest = (duration + settle) / limit
        reason = (f"{steps} physics steps asked for ((settle {settle:g} s + the plan's "
                  f"{duration:g} s) / timestep); at most {limit} are simulated "
                  f"(DEXROLL_SIM_MAX_STEPS): a timestep of at least {smallest:.3g} s")
        raise ServiceError(422, "invalid_request", f"timestep: {reason}",
                           [FieldError(field="timestep", reason=reason)])
    errors = _loop_errors(options, duration)
    if errors:
        raise ServiceError(422, "invalid_request", "; ".join(f"{f}: {r}" for f, r in errors),
                           [FieldError(field=f, reason=r) for f, r in errors])
    pool: SimulationPool = request.app.state.simulations
    report = await _outcome(request, pool, row.result, row.request,
                            options.simulator_options())
    body = SimulationReport.model_validate({**report, "job_id": job_id})
    text = body.model_dump_json()
    await asyncio.to_thread(store.put_simulation, job_id, text)
    return Response(text, status_code=201, media_type="application/json",
                    headers={"Location": _path(job_id)})


@router.get("/v1/plans/{job_id}/simulation", response_model=SimulationReport,
            responses={404: {"model": ErrorBody,
                             "description": "no such job, or not simulated yet"}})
def simulation_report(job_id: str, store: StoreDep, owner: OwnerDep) -> Response:
    """The latest simulation report of a job (404 until `POST` has run one)."""
    if store.head(job_id, owner) is None:
        raise ServiceError(404, "not_found", f"no job {job_id!r}")
    text = store.get_simulation(job_id)
    if text is None:
        raise ServiceError(404, "not_simulated", f"job {job_id} has not been simulated: "
                                                 f"POST {_path(job_id)}")
    return Response(text, media_type="application/json")
