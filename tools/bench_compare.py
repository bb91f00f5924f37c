"""Compare `dexroll bench` reports of two commits run in the same hour, interleaved
(old, new, old, new, ...): per family, the success counts, whether every problem took the
same IPOPT iterations, and the median solve time of each side with the ratio new / old.

    python tools/bench_compare.py --old A/results.json C/results.json \\
                                  --new B/results.json D/results.json

A problem's solve time on a side is the median over that side's runs; a family's is the
median over its problems. Prints a Markdown table (docs/performance.md keeps such tables).
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import defaultdict
from pathlib import Path
from typing import Any


def _rows(paths: list[str]) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for p in paths:
        out += [r for r in json.loads(Path(p).read_text())["rows"]
                if r["method"] == "collocation"]
    return out


def _by_problem(rows: list[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    out: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        out[(r["family"], r["problem_id"])].append(r)
    return out


def compare(old: list[str], new: list[str]) -> str:
    a, b = _by_problem(_rows(old)), _by_problem(_rows(new))
    families = sorted({f for f, _ in a} | {f for f, _ in b})
    lines = ["| family | problems | ok old | ok new | same iterations | median solve old [s] "
             "| median solve new [s] | new / old |", "|---|---:|---:|---:|---|---:|---:|---:|"]
    for fam in families:
        keys = sorted(k for k in a if k[0] == fam and k in b)
        ok_a = sum(all(r["ok"] for r in a[k]) for k in keys)
        ok_b = sum(all(r["ok"] for r in b[k]) for k in keys)
        differ = [k[1] for k in keys
                  if {r["iterations"] for r in a[k]} != {r["iterations"] for r in b[k]}]
        med_a = statistics.median(statistics.median(r["solve_time"] for r in a[k])
                                  for k in keys)
        med_b = statistics.median(statistics.median(r["solve_time"] for r in b[k])
                                  for k in keys)
        same = "yes" if not differ else f"no: {len(differ)} ({', '.join(differ[:3])})"
        lines.append(f"| {fam} | {len(keys)} | {ok_a} | {ok_b} | {same} | {med_a:.3f} | "
                     f"{med_b:.3f} | {med_b / med_a:.2f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", nargs="+", required=True, help="results.json of the old commit")
    ap.add_argument("--new", nargs="+", required=True, help="results.json of the new commit")
    args = ap.parse_args()
    print(compare(args.old, args.new))


if __name__ == "__main__":
    main()
