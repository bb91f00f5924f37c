"""The planner-agnostic entry points under their former path, for the benchmark harness
(``planner_service/bench/``: generators, peers, rows) alone; everything else imports
:mod:`planner_service.planners`. Remove once the harness imports them from there."""

from __future__ import annotations

from .planners import REQUEST, request_errors, solve, to_problem, validation_errors

__all__ = ["REQUEST", "request_errors", "solve", "to_problem", "validation_errors"]
