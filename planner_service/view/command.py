"""``dexroll view RESULT.json -o plan.html``: a plan's standalone page (docs/viewer.md).

RESULT.json is a result as ``dexroll plan`` writes it, or a job as ``GET /v1/plans/{id}``
answers it. ``--request`` names the plan's request: the object and fingers are then the
request's own; without it they are inferred from the result (a ball or ellipsoid fitted to
the contacts, the built-in fingers and hands matched by their pad poses).

Exit codes: 0 the page is written, 2 the files cannot be read or hold no plan.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pydantic import ValidationError

from . import NoPlanError, read_result, view_html

__all__ = ["add_arguments", "main"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("result", help="a result file (dexroll plan) or a job's JSON "
                                       "(GET /v1/plans/{id})")
    parser.add_argument("-o", "--output", help="the page (default: ./<result>.html)")
    parser.add_argument("--request", metavar="REQUEST.json",
                        help="the plan's request: draw its own object and fingers "
                             "(default: inferred from the result)")
    parser.add_argument("--title", help="the page's title (default: the file's name)")


def main(args: argparse.Namespace) -> int:
    from ..planners import REQUEST, ProblemError, validation_errors

    path = Path(args.result)
    request = None
    try:
        result, job_id = read_result(path)
        if args.request:
            raw = json.loads(Path(args.request).read_text(encoding="utf-8"))
            request = REQUEST.validate_python(raw)
        title = args.title or (f"job {job_id}" if job_id else path.name)
        page = view_html(result, request, title)
    except ValidationError as exc:
        reasons = "; ".join(f"{f}: {r}" for f, r in validation_errors(exc)[:5])
        print(f"{args.request} is not a valid request: {reasons}", file=sys.stderr)
        return 2
    except ProblemError as exc:
        print(f"the request's models cannot be loaded: {exc.errors}", file=sys.stderr)
        return 2
    except (OSError, ValueError, NoPlanError) as exc:
        print(str(exc), file=sys.stderr)
        return 2
    stem = path.name.removesuffix(".json")
    out = Path(args.output) if args.output else Path(f"{stem}.html")
    out.write_text(page, encoding="utf-8")
    print(f"{out} ({len(page.encode()) / 1e6:.2f} MB): open it in a browser")
    return 0
