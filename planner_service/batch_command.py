"""``dexroll batch FILE.jsonl``: many plan requests (one JSON a line) submitted to a
running service as one batch (``POST /v1/batches``), the jobs written as they finish to
an NDJSON file in the requests' order of finishing, a progress bar on stderr
(docs/service.md, "Batches").

Exit codes: 0 every job succeeded, 1 some did not (the file has each one's state and
code), 2 the file or a request in it is invalid (each bad field named with its line), 3
the service could not be reached or refused the batch.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_SERVICE = 0, 1, 2, 3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("requests", help="the requests: a JSON object a line (JSONL)")
    parser.add_argument("--url", default=os.environ.get("DEXROLL_URL",
                                                        "http://127.0.0.1:8000"),
                        help="the service (default $DEXROLL_URL or http://127.0.0.1:8000)")
    parser.add_argument("--api-key", default=os.environ.get("DEXROLL_API_KEY"),
                        help="the service's API key (default $DEXROLL_API_KEY)")
    parser.add_argument("-o", "--output",
                        help="the jobs as they finish, a JSON a line (default "
                             "<requests>.results.jsonl)")
    parser.add_argument("--no-plans", action="store_true",
                        help="write the jobs without their plans")


def _bar(done: int, total: int, failed: int, started: float) -> str:
    width = 30
    filled = int(width * done / max(total, 1))
    return (f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} done, "
            f"{failed} not succeeded, {time.monotonic() - started:.0f} s")


def main(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from dexroll_client import DexrollClient
    from dexroll_client.errors import APIError, InvalidRequestError, TransportError

    path = Path(args.requests)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        print(f"{path}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_INVALID
    requests: list[Any] = []
    numbers: list[int] = []
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            requests.append(json.loads(line))
        except json.JSONDecodeError as exc:
            print(f"{path}:{n}: not valid JSON: {exc.msg}", file=sys.stderr)
            return EXIT_INVALID
        numbers.append(n)
    if not requests:
        print(f"{path}: no requests in it", file=sys.stderr)
        return EXIT_INVALID
    out = Path(args.output) if args.output else path.with_suffix(".results.jsonl")
    started = time.monotonic()
    done = failed = 0
    try:
        with DexrollClient.from_url(args.url, api_key=args.api_key) as client:
            batch = client.submit_batch(requests)
            print(f"batch {batch.id}: {batch.size} jobs", file=sys.stderr)
            with out.open("w", encoding="utf-8") as f:
                for job in client.batch_results(batch.id, order="finished",
                                                result=not args.no_plans):
                    done += 1
                    failed += job.state.value != "succeeded"
                    f.write(job.model_dump_json() + "\n")
                    f.flush()
                    print(_bar(done, batch.size, failed, started), end="", file=sys.stderr,
                          flush=True)
    except ValidationError as exc:  # checked here, before anything is sent
        for e in exc.errors():
            loc = list(e["loc"])
            where = f"line {numbers[int(loc[1])]}" if len(loc) > 1 and loc[0] == "items" \
                else "the batch"
            rest = ".".join(str(p) for p in loc[2:])
            print(f"{path}: {where}: {rest or 'request'}: {e['msg']}", file=sys.stderr)
        return EXIT_INVALID
    except InvalidRequestError as exc:
        for d in exc.detail or []:
            field = d.field
            if field.startswith("items["):  # the item's line in the file
                i = int(field[6:field.index("]")])
                field = f"line {numbers[i]}: {field[field.index(']') + 2:]}"
            print(f"{path}: {field}: {d.reason}", file=sys.stderr)
        if not exc.detail:
            print(f"{path}: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except (APIError, TransportError) as exc:
        print(f"\n{args.url}: {exc}", file=sys.stderr)
        return EXIT_SERVICE
    print(f"\n{out}: {done} jobs, {done - failed} succeeded", file=sys.stderr)
    return EXIT_OK if failed == 0 else EXIT_FAILED
