"""``/v1/plans/{id}/simulation``: a finished job's plan executed in MuJoCo, its report
stored beside the plan (docs/simulation.md).

``POST`` runs the simulation (options in the body; a few seconds of the service's CPU,
one run at a time per service process, plans of up to 120 s) and answers 201 with the
report, which it stores as the job's latest; ``GET`` answers the stored report. A job
without a plan a hand executes (still running, failed without a plan, a ball-on-palm
plan, a plan too long to simulate here) is a 409; a service installed without MuJoCo
(the ``sim`` extra) answers 503.
"""

from __future__ import annotations

import threading
from typing import Any

from fastapi import APIRouter
from fastapi.responses import Response

from dexroll_client.models import ErrorBody, JobState
from dexroll_client.simulation import SimulationOptions, SimulationReport

from ...execution import NotExecutableError, execution_plan
from ...planners import REQUEST, RESULT, ProblemError
from ..access import OwnerDep
from ..deps import ServiceError, StoreDep

__all__ = ["router"]

router = APIRouter()

#: One simulation at a time per process (each takes a core for a few seconds).
_running = threading.Lock()
#: The longest plan simulated here [s] (about a minute of the API process's core at
#: 0.5 ms steps); a longer one: ``dexroll simulate`` on its result.
MAX_SIMULATED_DURATION = 120.0

_RESPONSES: dict[int | str, dict[str, Any]] = {
    409: {"model": ErrorBody,
          "description": "the job has not finished, or has no plan a hand executes"},
    503: {"model": ErrorBody,
          "description": "this service was installed without MuJoCo (the `sim` extra)"},
}


def _path(job_id: str) -> str:
    return f"/v1/plans/{job_id}/simulation"


@router.post("/v1/plans/{job_id}/simulation", status_code=201,
             response_model=SimulationReport, responses=_RESPONSES)
def simulate_plan(job_id: str, store: StoreDep, owner: OwnerDep,
                  options: SimulationOptions | None = None) -> Response:
    """Execute a finished job's plan in MuJoCo with the plan's own hand, object and
    friction: the fingers' joints follow the plan through position servos (or are set to
    it: `mode`), with a grip (`squeeze`, `grip_force`; a plan's own forces when it has
    them). The report (the object's position and orientation errors over time, every
    contact's losses, slip and normal force, pass or fail against `tolerances`) is stored
    as the job's latest (`GET` answers it)."""
    row = store.get(job_id, owner)
    if row is None:
        raise ServiceError(404, "not_found", f"no job {job_id!r}")
    if not JobState(row.state).terminal:
        raise ServiceError(409, "not_finished", f"job {job_id} is {row.state}: it can be "
                                                "simulated once it has finished",
                           headers={"Retry-After": "1"})
    if row.result is None:
        raise ServiceError(409, "no_plan", f"job {job_id} ended ({row.state}) without a plan")
    options = options or SimulationOptions()
    try:
        from sim import SimOptions, simulate  # MuJoCo: the sim extra
    except ImportError as exc:
        raise ServiceError(503, "simulation_unavailable",
                           "this service was installed without MuJoCo: pip install "
                           "'dexroll[sim]'") from exc
    try:
        result = RESULT.validate_json(row.result)
        request = REQUEST.validate_json(row.request)
        plan = execution_plan(result, request)
        if plan.duration > MAX_SIMULATED_DURATION:
            raise ServiceError(409, "too_long", f"job {job_id}: a plan of {plan.duration:g} s "
                                                f"is longer than the "
                                                f"{MAX_SIMULATED_DURATION:g} s this service "
                                                "simulates: run `dexroll simulate` on its "
                                                "result")
        sim_options = SimOptions.from_dict(options.simulator_options())
        with _running:
            report = simulate(plan, sim_options)
    except (NotExecutableError, ProblemError) as exc:
        raise ServiceError(409, "not_executable", f"job {job_id}: {exc}") from exc
    except ValueError as exc:  # an option the simulator refuses (solref vs timestep, ...)
        raise ServiceError(422, "invalid_options", str(exc)) from exc
    body = SimulationReport.model_validate({**report.to_dict(), "job_id": job_id})
    text = body.model_dump_json()
    store.put_simulation(job_id, text)
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
