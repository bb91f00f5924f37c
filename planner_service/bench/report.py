"""The report of a benchmark run: ``results.json`` (rows, summary, suite, problems, machine,
versions), ``results.csv`` (the rows), ``report.md`` (a table per family and method, the
failures, plots ``success_rate.png`` and ``solve_times.png``)."""

from __future__ import annotations

import csv
import datetime as dt
import importlib.metadata
import json
import math
import os
import platform
import subprocess
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .rows import FIELDS
from .suite import METHODS

__all__ = ["machine_info", "ratios", "summarise", "versions", "write_report"]

#: The method the others are compared with (the project's planner).
REFERENCE = "collocation"

Row = dict[str, Any]

#: Residuals summarised over the solved rows: field -> (column title, worst is max?).
_RESIDUALS: tuple[tuple[str, str, bool], ...] = (
    ("goal_error_max", "goal error max", True),
    ("cert_slip_speed_max", "slip max [m/s]", True),
    ("cert_spin_rate_max", "spin max [rad/s]", True),
    ("cert_closure_position_max", "closure max [m]", True),
    ("cert_closure_orientation_max", "closure max [rad]", True),
    ("cert_position_defect_max", "defect max [m]", True),
    ("cert_angle_defect_max", "defect max [rad]", True),
    ("cert_cone_margin_min", "cone margin min [rad]", False),
)
#: The status of a peer's run on a problem it does not model (e.g. Drake and an ellipsoid):
#: kept as a row, left out of the counts and rates.
UNAVAILABLE = "unavailable"
_PACKAGES = ("dexroll", "dexroll-client", "casadi", "numpy", "pin", "pydantic", "httpx",
             "fastapi", "matplotlib", "ray", "drake", "mujoco")


def _values(rows: Iterable[Row], key: str) -> list[float]:
    return [float(r[key]) for r in rows if r.get(key) is not None]


def _method_order(method: str) -> int:
    return METHODS.index(method) if method in METHODS else len(METHODS)


def _solvers(rows: Sequence[Row]) -> str | None:
    """The NLP solvers of a family's rows: one name, or each with its count ("fatrop 18,
    ipopt (fatrop: ...) 2") when they differ; None when no row names one."""
    names = [str(r["solver"]) for r in rows if r.get("solver")]
    if not names:
        return None
    counts: dict[str, int] = {}
    for n in names:
        counts[n] = counts.get(n, 0) + 1
    if len(counts) == 1:
        return names[0]
    return ", ".join(f"{n} {c}" for n, c in sorted(counts.items(), key=lambda kv: -kv[1]))


def summarise(rows: Sequence[Row], families: Sequence[str] = ()) -> list[dict[str, Any]]:
    """One entry per (family, method), in the order of ``families`` (the suite's; others
    after them, by name) then in ``METHODS`` order. Times over every
    row that has one; iterations over every row; goal errors and certificate residuals over
    the rows that solved with a passed certificate (a failed plan's residuals say little)."""
    groups: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        groups.setdefault((r["family"], r["method"]), []).append(r)
    order = {f: i for i, f in enumerate(families)}
    out = []
    for (family, method) in sorted(groups, key=lambda k: (order.get(k[0], len(order)), k[0],
                                                          _method_order(k[1]))):
        every = groups[(family, method)]
        g = [r for r in every if r["status"] != UNAVAILABLE]
        ok = [r for r in g if r["ok"]]
        solve = _values(g, "solve_time")
        build = _values(g, "build_time")
        wall = _values(g, "wall_time")
        iters = _values(g, "iterations")
        entry: dict[str, Any] = {
            "family": family, "method": method, "count": len(g), "ok": len(ok),
            "unavailable": len(every) - len(g),
            "success_rate": len(ok) / len(g) if g else None,
            "expected_solved_failed": sum(1 for r in every if r["expected"] == "solved"
                                          and not r["ok"]),
            "solve_time_median": float(np.median(solve)) if solve else None,
            "solve_time_p90": float(np.percentile(solve, 90)) if solve else None,
            "solve_time_max": max(solve) if solve else None,
            "build_time_sum": math.fsum(build) if build else None,
            "build_time_max": max(build) if build else None,
            "wall_time_median": float(np.median(wall)) if wall else None,
            "iterations_median": float(np.median(iters)) if iters else None,
            "solver": _solvers(g),
            "peak_rss_mb_max": max(_values(g, "peak_rss_mb"), default=None),
        }
        for key, _, worst_is_max in _RESIDUALS:
            vals = _values(ok, key)
            entry[key] = (max(vals) if worst_is_max else min(vals)) if vals else None
        entry.update(_executions(g))
        out.append(entry)
    return out


def _executions(rows: Sequence[Row]) -> dict[str, Any]:
    """The executions in MuJoCo of a group's solved plans (docs/simulation.md): how many
    ran, how many passed, the worst position [m] and orientation [rad] errors."""
    ran = [r for r in rows if r.get("exec_status") in ("passed", "failed", "error")]
    return {"executed": len(ran),
            "executed_passed": sum(1 for r in ran if r["exec_status"] == "passed"),
            "exec_position_error_max": max(_values(ran, "exec_position_error_max"),
                                           default=None),
            "exec_angle_error_max": max(_values(ran, "exec_angle_error_max"), default=None)}


def _fmt_executed(s: dict[str, Any]) -> str:
    if not s.get("executed"):
        return "–"
    text = f"{s['executed_passed']}/{s['executed']}"
    if s["exec_position_error_max"] is not None and s["exec_angle_error_max"] is not None:
        text += (f" ({s['exec_position_error_max'] * 1e3:.2f} mm, "
                 f"{math.degrees(s['exec_angle_error_max']):.2f}°)")
    return text


def ratios(rows: Sequence[Row], summary: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each other method against :data:`REFERENCE`, per family, measured in this run: how
    many times longer its solves took (> 1: the reference is faster).

    ``ratio_of_medians``: the method's median solve time over the reference's (each over
    all its runs in the family, as in the summary); ``paired_median``: the median of the
    per-problem ratio over the ``paired`` problems both solved with a passed certificate
    (a plan that failed its certificate, or that the reference had to refine, is not the
    same work)."""
    by = {(s["family"], s["method"]): s for s in summary}
    per_problem: dict[tuple[str, str], Row] = {(r["problem_id"], r["method"]): r
                                               for r in rows}
    out = []
    for s in summary:
        ref = by.get((s["family"], REFERENCE))
        if s["method"] == REFERENCE or ref is None:
            continue
        mine = [r for r in rows if r["family"] == s["family"] and r["method"] == s["method"]]
        pairs = [(per_problem[(r["problem_id"], REFERENCE)], r) for r in mine
                 if (r["problem_id"], REFERENCE) in per_problem]
        timed = [b["solve_time"] / a["solve_time"] for a, b in pairs
                 if a["ok"] and b["ok"] and a.get("solve_time") and b.get("solve_time")]
        tm, rm = s["solve_time_median"], ref["solve_time_median"]
        out.append({"family": s["family"], "method": s["method"], "reference": REFERENCE,
                    "reference_median": rm, "method_median": tm,
                    "ratio_of_medians": tm / rm if tm and rm else None,
                    "paired_median": float(np.median(timed)) if timed else None,
                    "paired": len(timed)})
    return out


# -- machine and versions ---------------------------------------------------------------------

def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _memory_gib() -> float | None:
    try:
        return round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (ValueError, OSError, AttributeError):
        return None


def _git() -> dict[str, Any]:
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return {}
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                                capture_output=True, text=True, timeout=10, check=True)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--",
                                "ocp", "planner_service"], capture_output=True, text=True,
                               timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return {}
    return {"commit": commit.stdout.strip(), "dirty": bool(dirty.stdout.strip())}


def machine_info() -> dict[str, Any]:
    """The machine this process runs on (with --url or --ray the plans ran elsewhere too)."""
    return {"platform": platform.platform(), "machine": platform.machine(),
            "cpu": _cpu_model(), "cpus": os.cpu_count(), "memory_gib": _memory_gib(),
            "python": platform.python_version(), **_git()}


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


# -- files ------------------------------------------------------------------------------------

def _csv_value(key: str, value: Any) -> Any:
    if key == "failures":
        return "; ".join(value or [])
    if key == "certificate":
        return json.dumps(value or {}, sort_keys=True)
    return "" if value is None else value


def _write_csv(path: Path, rows: Sequence[Row]) -> None:
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(FIELDS)
        for r in rows:
            writer.writerow([_csv_value(k, r.get(k)) for k in FIELDS])


def _fmt_time(x: float | None) -> str:
    if x is None:
        return "–"
    return f"{x * 1e3:.0f} ms" if x < 1.0 else f"{x:.2f} s"


def _fmt(x: float | None, spec: str = ".2e") -> str:
    return "–" if x is None else format(x, spec)


def _table(summary: Sequence[dict[str, Any]]) -> list[str]:
    head = ["family", "method", "solver", "n", "success", "solve median", "p90", "max",
            "build (sum)", "iterations median"] + [title for _, title, _ in _RESIDUALS] + \
        ["executed (worst mm, deg)"]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join(["---"] * 3 + ["---:"] * (len(head) - 3)) + "|"]
    for s in summary:
        rate = "–" if s["success_rate"] is None else \
            f"{s['ok']}/{s['count']} ({100 * s['success_rate']:.0f} %)"
        if s["unavailable"]:
            rate += f" ({s['unavailable']} unavailable)"
        cells = [s["family"], s["method"], s.get("solver") or "–", str(s["count"]), rate,
                 _fmt_time(s["solve_time_median"]), _fmt_time(s["solve_time_p90"]),
                 _fmt_time(s["solve_time_max"]), _fmt_time(s["build_time_sum"]),
                 _fmt(s["iterations_median"], ".0f")]
        cells += [_fmt(s[key], ".3f" if key == "cert_cone_margin_min" else ".2e")
                  for key, _, _ in _RESIDUALS]
        cells.append(_fmt_executed(s))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _plots(out: Path, rows: Sequence[Row], summary: Sequence[dict[str, Any]]
           ) -> tuple[list[str], str | None]:
    """success_rate.png and solve_times.png; (file names, why there are none)."""
    if not rows:
        return [], "no runs"
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return [], "matplotlib is not installed (pip install 'dexroll[figures]'): no plots"
    families = list(dict.fromkeys(s["family"] for s in summary))
    methods = sorted({s["method"] for s in summary}, key=_method_order)
    by = {(s["family"], s["method"]): s for s in summary}
    width = 0.8 / max(len(methods), 1)
    colors = {m: f"C{i}" for i, m in enumerate(methods)}

    fig = Figure(figsize=(max(6.0, 1.3 * len(families) + 2), 4.0), layout="constrained")
    FigureCanvasAgg(fig)  # headless: the Agg canvas, no pyplot, no display
    ax = fig.add_subplot()
    for j, m in enumerate(methods):
        xs, hs, labels = [], [], []
        for i, f in enumerate(families):
            s = by.get((f, m))
            if s is not None and s["success_rate"] is not None:
                xs.append(i + (j - (len(methods) - 1) / 2) * width)
                hs.append(100 * s["success_rate"])
                labels.append(f"{s['ok']}/{s['count']}")
        bars = ax.bar(xs, hs, width, label=m, color=colors[m])
        ax.bar_label(bars, labels, fontsize=7)
    ax.set_xticks(range(len(families)), families, rotation=20, ha="right")
    ax.set_ylabel("solved with a passed certificate [%]")
    ax.set_ylim(0, 112)
    ax.set_title("Success rate per family and method")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.savefig(out / "success_rate.png", dpi=110)

    fig = Figure(figsize=(max(6.0, 1.3 * len(families) + 2), 4.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)  # jitter of the points only
    plotted = 0
    for j, m in enumerate(methods):
        for i, f in enumerate(families):
            times = [r["solve_time"] for r in rows if r["family"] == f and r["method"] == m
                     and r.get("solve_time")]
            if not times:
                continue
            x = i + (j - (len(methods) - 1) / 2) * width
            ax.boxplot([times], positions=[x], widths=0.8 * width, showfliers=False,
                       medianprops={"color": colors[m]})
            ok = np.array([bool(r["ok"]) for r in rows if r["family"] == f
                           and r["method"] == m and r.get("solve_time")])
            px = x + rng.uniform(-0.25, 0.25, len(times)) * width
            ts = np.array(times)
            plotted += len(ts)
            ax.scatter(px[ok], ts[ok], s=12, color=colors[m], zorder=3, alpha=0.8)
            ax.scatter(px[~ok], ts[~ok], s=30, color="black", marker="x", zorder=4)
    for m in methods:
        ax.scatter([], [], color=colors[m], label=m, s=12)
    ax.scatter([], [], color="black", marker="x", label="not solved", s=30)
    if plotted:
        ax.set_yscale("log")
    else:  # e.g. only a peer that models none of the suite's problems
        ax.text(0.5, 0.5, "no run reported a solve time", transform=ax.transAxes,
                ha="center")
    ax.set_xticks(range(len(families)), families, rotation=20, ha="right")
    ax.set_ylabel("solve time [s] (log)")
    ax.set_title("Solve time per family and method")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.savefig(out / "solve_times.png", dpi=110)
    return ["success_rate.png", "solve_times.png"], None


def write_report(out: Path, rows: Sequence[Row], meta: dict[str, Any],
                 problems: Sequence[dict[str, Any]], views: bool = False) -> dict[str, Any]:
    """Write the report's files into ``out``; the results document (results.json's).
    ``views``: also the views of each family's best and worst plan (:mod:`.views`: they
    are planned again in this process), linked from the report."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarise(rows, list(dict.fromkeys(p["family"] for p in problems)))
    unexpected = [r for r in rows if r["expected"] == "solved" and not r["ok"]]
    fixed = [r for r in rows if r["expected"] == "unsolved" and r["ok"]]
    plots, no_plots = _plots(out, rows, summary)
    doc = {**meta, "summary": summary, "ratios": ratios(rows, summary),
           "problems": list(problems), "rows": list(rows),
           "unexpected_failures": [[r["family"], r["problem_id"], r["method"]]
                                   for r in unexpected],
           "plots": plots}
    if views:
        from .views import write_views

        doc["views"] = write_views(out, rows, problems)
    (out / "results.json").write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n",
                                      encoding="utf-8")
    _write_csv(out / "results.csv", rows)
    (out / "report.md").write_text(_markdown(doc, summary, unexpected, fixed, plots, no_plots),
                                   encoding="utf-8")
    return doc


def _markdown(doc: dict[str, Any], summary: Sequence[dict[str, Any]], unexpected: list[Row],
              fixed: list[Row], plots: list[str], no_plots: str | None) -> str:
    rows: list[Row] = doc["rows"]
    run, machine, suite = doc["run"], doc["machine"], doc["suite"]
    n_ok = sum(1 for r in rows if r["ok"])
    lines = [f"# Benchmark `{suite['name']}`", ""]
    if suite.get("description"):
        lines += [suite["description"], ""]
    where = {"pool": f"the library, a local pool of {run['workers']} worker process(es)",
             "service": f"the service at {run.get('url')} ({run['workers']} jobs in flight)",
             "ray": f"Ray ({run.get('ray', {}).get('actors')} actor(s), address "
                    f"{run.get('ray', {}).get('address')})"}[run["runner"]]
    lines += [
        f"- **run**: {run['started']} through {where}; {run['wall_time']:.1f} s wall; "
        f"suite {suite['source']}"
        + (f", families {', '.join(run['families'])}" if run.get("families") else "")
        + (f", first {run['limit']} per family" if run.get("limit") is not None else ""),
        f"- **machine**: {machine['cpu']}, {machine['cpus']} CPUs, {machine['memory_gib']} GiB,"
        f" {machine['platform']}, Python {machine['python']}"
        + (f", commit {machine['commit'][:10]}{' (dirty)' if machine.get('dirty') else ''}"
           if machine.get("commit") else ""),
        "- **versions**: " + ", ".join(f"{k} {v}" for k, v in doc["versions"].items() if v),
        f"- **outcome**: {n_ok}/{len(rows)} runs solved with a passed certificate; "
        + (f"**{len(unexpected)} expected to solve did not** (exit code 1)" if unexpected
           else "every run expected to solve did (exit code 0)"),
    ]
    for method, why in doc.get("skipped_methods", {}).items():
        lines.append(f"- **skipped**: `{method}`: {why}")
    lines += [f"- {note}" for note in run.get("notes", [])]
    lines += ["", "## Per family and method", ""]
    lines += _table(summary)
    lines += ["", "Success: solved (the solver converged) **and** the certificate passed. "
              "Times over every run (`solve`: the planner's solve time, initial guesses and "
              "IPOPT over all attempts and refinements, or the greedy method's steps; `build`: "
              "NLP construction, 0 when a worker had the NLP cached); goal errors and "
              "certificate residuals are the worst over the successful runs (cone margin: "
              "the smallest; > 0 is inside the friction cones). Greedy iterations are its "
              "steps. Executed: the successful plans with fingers run in MuJoCo by a hand "
              "following them (docs/simulation.md: position servos, "
              + ("the plans' own forces as feed-forward (planned with `--forces` "
                 f"{run['forces']}; the greedy method's with a 0.5 mm squeeze and 1 N grip)"
                 if run.get("forces") else "a 0.5 mm squeeze and 1 N grip")
              + "), passed within 1 mm and 2° with no contact lost / run, and the "
              "worst object errors."]
    if doc["ratios"]:
        lines += ["", f"## Against `{REFERENCE}`, in this run", "",
                  f"How many times longer each method's solves took than `{REFERENCE}`'s "
                  "(> 1: it is slower), per family: the ratio of the median solve times over "
                  "all runs, and the median of the per-problem ratios over the problems both "
                  "solved with a passed certificate.", "",
                  "| family | method | its median | reference median | ratio of medians | "
                  "paired median ratio | problems both solved |",
                  "|---|---|---:|---:|---:|---:|---:|"]
        lines += [f"| {q['family']} | {q['method']} | {_fmt_time(q['method_median'])} | "
                  f"{_fmt_time(q['reference_median'])} | {_fmt(q['ratio_of_medians'], '.2f')} | "
                  f"{_fmt(q['paired_median'], '.2f')} | {q['paired']} |"
                  for q in doc["ratios"]]
    if plots:
        lines += ["", "## Plots", ""] + [f"![{p}]({p})" for p in plots]
    elif no_plots:
        lines += ["", f"No plots: {no_plots}."]
    lines += _views_section(doc.get("views"))

    def failure_table(title: str, failed: list[Row]) -> list[str]:
        out = ["", f"## {title}", "", "| problem | method | expected | status | why |",
               "|---|---|---|---|---|"]
        for r in failed:
            why = "; ".join(r["failures"]) or r["message"] or ""
            out.append(f"| {r['problem_id']} | {r['method']} | {r['expected']} | "
                       f"{r['status']} | {why.replace('|', '/')[:300]} |")
        return out

    if unexpected:
        lines += failure_table("Runs expected to solve that did not", unexpected)
    others = [r for r in rows if not r["ok"] and r["expected"] != "solved"
              and r["status"] != UNAVAILABLE]
    if others:
        lines += failure_table("Other runs not solved (expected: unsolved or any)", others)
    missing: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        if r["status"] == UNAVAILABLE and r["expected"] != "solved":
            missing.setdefault((r["family"], r["method"]), []).append(r)
    if missing:
        lines += ["", "Not modelled by the method (status `unavailable`, left out of the "
                      "counts):"]
        lines += [f"- {family}, {method}: {len(rs)} problem(s): {rs[0]['message']}"
                  for (family, method), rs in missing.items()]
    failed_runs = [r for r in rows if r.get("exec_status") in ("failed", "error")]
    if failed_runs:
        lines += ["", "## Solved plans whose execution in MuJoCo failed", "",
                  "| family | problem | method | execution | position worst | angle worst | "
                  "why |", "|---|---|---|---|---:|---:|---|"]
        for r in failed_runs:
            pos, ang = r.get("exec_position_error_max"), r.get("exec_angle_error_max")
            lines.append(
                f"| {r['family']} | {r['problem_id']} | {r['method']} | {r['exec_status']} | "
                f"{'–' if pos is None else f'{pos * 1e3:.3f} mm'} | "
                f"{'–' if ang is None else f'{math.degrees(ang):.3f}°'} | "
                f"{(r.get('exec_message') or '').replace('|', '/')[:200]} |")
    if unexpected or others:
        lines += ["", "Each problem's request is in `results.json` (`problems`)."]
    if fixed:
        lines += ["", "Expected not to solve but solved (update the suite): "
                  + ", ".join(f"{r['problem_id']} ({r['method']})" for r in fixed)]
    commented = [(p["id"], m, c) for p in doc["problems"]
                 for m, c in p.get("comments", {}).items()]
    if commented:
        lines += ["", "## Known failures the suite expects", ""]
        lines += [f"- {pid} ({m}): {c}" for pid, m, c in commented]
    return "\n".join(lines) + "\n"


def _views_section(views: list[dict[str, Any]] | None) -> list[str]:
    """The report's links to the views of each family's best and worst plan."""
    if not views:
        return []
    lines = ["", "## Views of the plans", "",
             "Each family's best run (the fastest that succeeded) and worst (the first that "
             "did not succeed, else the slowest), as animated 3D views (standalone pages: "
             "open them in a browser; docs/viewer.md).", "",
             "| family | which | problem | method | status | solve | view |",
             "|---|---|---|---|---|---:|---|"]
    for v in views:
        link = f"[{v['path']}]({v['path']})" if v["path"] else f"none: {v['error']}"
        lines.append(f"| {v['family']} | {v['which']} | {v['problem_id']} | {v['method']} | "
                     f"{v['status']} | {_fmt_time(v['solve_time'])} | "
                     f"{link.replace('|', '/')[:300]} |")
    return lines


def now_utc() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
