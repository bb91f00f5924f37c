"""What a simulated execution reports: the object's position and orientation error against
the plan over time (worst, final, RMS), every planned contact's losses, slip and normal
force, and pass or fail against the tolerances; as JSON (:meth:`SimReport.to_dict`) and
as a figure of the errors over time (:func:`plot`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .options import SimOptions

__all__ = ["ContactReport", "ErrorSummary", "SimReport", "plot"]


@dataclass(frozen=True)
class ErrorSummary:
    """An error over the plan's horizon: its worst value, at ``worst_at`` [s], its final
    value and its RMS (units: m or rad)."""

    max: float
    worst_at: float | None
    final: float
    rms: float

    @staticmethod
    def of(values: np.ndarray, times: np.ndarray | None = None) -> ErrorSummary:
        if values.size == 0:
            return ErrorSummary(0.0, None, 0.0, 0.0)
        k = int(np.argmax(values))
        return ErrorSummary(float(values[k]), None if times is None else float(times[k]),
                            float(values[-1]), float(np.sqrt(np.mean(values**2))))


@dataclass(frozen=True)
class ContactReport:
    """One planned contact during the plan (from t = 0): ``lost_time`` [s] in all without
    touching (no normal force) in ``loss_events`` separate losses, the first at
    ``first_loss_at`` [s]; ``slip_distance`` [m], the integral of the tangential speed of
    the object's material point relative to the touching body at the contact, and its
    worst speed [m/s]; the normal force [N] (its sum over the pair's contact points) and,
    when the plan states the contact's force, the planned normal force's mean and the
    worst difference between the two (None otherwise)."""

    name: str
    body: str
    lost_time: float
    loss_events: int
    first_loss_at: float | None
    slip_distance: float
    max_slip_speed: float
    normal_force_min: float
    normal_force_mean: float
    normal_force_max: float
    planned_normal_force_mean: float | None = None
    normal_force_error_max: float | None = None
    #: time [s] the fingertip touched the object while the plan has it lifted
    unplanned_touch_time: float = 0.0
    #: the largest distance [m] between the touching bodies at a step counted as a loss
    #: (a flicker of a stiff contact: micrometres; a fingertip let go: millimetres; None:
    #: no loss, or not measured)
    lost_separation_max: float | None = None


@dataclass
class SimReport:
    """A simulated execution (see the module). ``series``: the recorded times [s] (from
    -settle), the position [m] and angle [rad] errors there, each contact's normal force
    [N]."""

    passed: bool
    failures: list[str]
    mode: str
    position_error: ErrorSummary
    angle_error: ErrorSummary
    contacts: list[ContactReport]
    tolerances: dict[str, float]
    options: dict[str, Any]
    duration: float
    steps: int
    wall_time: float
    mujoco_version: str
    notes: list[str] = field(default_factory=list)
    series: dict[str, Any] = field(default_factory=dict)
    #: executed on the user's own model (:mod:`.user_model`): its scene's and drive's
    #: settings, the torques needed against the actuators' ranges; None: dexroll's scene
    model: dict[str, Any] | None = None

    @staticmethod
    def assess(*, mode: str, options: SimOptions, contacts: list[ContactReport],
               position: ErrorSummary, angle: ErrorSummary, series_t: np.ndarray,
               series_position: np.ndarray, series_angle: np.ndarray,
               series_force: np.ndarray, wall_time: float, steps: int, duration: float,
               notes: list[str], mujoco_version: str) -> SimReport:
        tol = options.tolerances
        failures = []
        if not position.max <= tol.position:
            failures.append(f"position error {position.max * 1e3:.3g} mm > "
                            f"{tol.position * 1e3:.3g} mm")
        if not angle.max <= tol.angle:
            failures.append(f"orientation error {math.degrees(angle.max):.3g} deg > "
                            f"{math.degrees(tol.angle):.3g} deg")
        for c in contacts:
            if c.lost_time > tol.contact_loss:
                apart = "" if c.lost_separation_max is None else \
                    f"; apart by at most {c.lost_separation_max * 1e3:.3g} mm"
                failures.append(f"contact {c.name} lost for {c.lost_time:.4g} s "
                                f"({c.loss_events} times, first at t = "
                                f"{c.first_loss_at:.4g} s{apart})")
            if c.unplanned_touch_time > tol.contact_loss:
                failures.append(f"fingertip {c.name} touched the object for "
                                f"{c.unplanned_touch_time:.4g} s while the plan has it "
                                "lifted")
        series = {"t": series_t.tolist(), "position_error": series_position.tolist(),
                  "angle_error": series_angle.tolist(),
                  "normal_force": {c.name: series_force[j].tolist()
                                   for j, c in enumerate(contacts)}}
        return SimReport(not failures, failures, mode, position, angle, contacts,
                         {"position": tol.position, "angle": tol.angle,
                          "contact_loss": tol.contact_loss},
                         options.to_dict(), duration, steps, wall_time, mujoco_version,
                         notes, series)

    @property
    def contacts_lost(self) -> int:
        return sum(1 for c in self.contacts if c.lost_time > 0)

    def summary(self) -> str:
        """A few lines for a terminal."""
        lines = [f"execution    {'PASSED' if self.passed else 'FAILED'} ({self.mode}, "
                 f"{self.duration:.3g} s simulated in {self.wall_time:.2f} s)",
                 f"position     {self.position_error.max * 1e3:.3f} mm worst, "
                 f"{self.position_error.final * 1e3:.3f} mm final",
                 f"orientation  {math.degrees(self.angle_error.max):.3f} deg worst, "
                 f"{math.degrees(self.angle_error.final):.3f} deg final"]
        for c in self.contacts:
            lines.append(f"contact {c.name:<6} lost {c.lost_time:.3g} s, slip "
                         f"{c.slip_distance * 1e3:.3f} mm, normal force "
                         f"{c.normal_force_min:.3g}..{c.normal_force_max:.3g} N")
        lines += [f"  {f}" for f in self.failures]
        if self.model is not None:
            lines += _model_summary(self.model)
        return "\n".join(lines)

    def to_dict(self, series: bool = True) -> dict[str, Any]:
        out = asdict(self)
        if not series:
            out.pop("series")
        return _finite(out)


def _model_summary(model: dict[str, Any]) -> list[str]:
    """The lines of a run on the user's model: what was changed, the contacts' settings
    that differ from the file's, the torques needed against the actuators."""
    lines = [f"model        the user's MJCF: {len(model['meshes_removed'])} mesh geoms "
             f"removed, timestep {model['timestep']:g} s (file {model['file_timestep']:g} "
             f"s), {model['integrator']}, cone {model['cone']}, impratio "
             f"{model['impratio']:g}, hand {model['hand_mass']:.3g} kg"]
    for t in model["fingertip_contacts"]:
        if t["differs"]:
            diff = ", ".join(f"{k} {t['file'][k]} -> {t['with_object'][k]}"
                             for k in t["differs"])
            lines.append(f"  contact {t['geom']}: {diff} (file -> with the object)")
    kinds: dict[str, int] = {}
    for e in model["drive"]:
        kinds[e["kind"]] = kinds.get(e["kind"], 0) + 1
    lines.append("  drive      " + ", ".join(f"{n} {k}" for k, n in sorted(kinds.items())))
    for e in model.get("torque", []):
        rng = e.get("torque_range")
        if rng is not None and (e["feedforward_max"] > max(abs(rng[0]), abs(rng[1]))
                                or e.get("saturated_fraction", 0.0) > 0):
            lines.append(f"  torque     {e['joint']}: needs {e['feedforward_max']:.3g} N m, "
                         f"range {rng[0]:.3g}..{rng[1]:.3g}, at its limit "
                         f"{100 * e.get('saturated_fraction', 0.0):.0f}% of the plan")
    if model.get("unplanned_contacts"):
        lines.append("  unplanned  " + ", ".join(
            f"{b} up to {f:.3g} N" for b, f in model["unplanned_contacts"].items()))
    return lines


def _finite(x: Any) -> Any:
    """JSON-safe: non-finite floats as None."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    return x


def plot(report: dict[str, Any], path: Path, title: str = "") -> None:
    """The position and orientation errors (and normal forces) over time, as a PNG
    (matplotlib, the ``figures`` extra)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = report["series"]
    t = np.asarray(s["t"], dtype=float)
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    tol = report["tolerances"]
    axes[0].plot(t, np.asarray(s["position_error"], dtype=float) * 1e3)
    axes[0].axhline(tol["position"] * 1e3, color="r", ls="--", lw=0.8, label="tolerance")
    axes[0].set_ylabel("position error [mm]")
    axes[0].legend(loc="upper left")
    axes[1].plot(t, np.degrees(np.asarray(s["angle_error"], dtype=float)))
    axes[1].axhline(math.degrees(tol["angle"]), color="r", ls="--", lw=0.8)
    axes[1].set_ylabel("orientation error [deg]")
    for name, f in s["normal_force"].items():
        axes[2].plot(t, f, label=name)
    axes[2].set_ylabel("normal force [N]")
    axes[2].set_xlabel("time [s] (settling before 0)")
    axes[2].legend(loc="upper left")
    for ax in axes:
        ax.axvline(0.0, color="k", lw=0.5)
        ax.grid(alpha=0.3)
    verdict = "passed" if report["passed"] else "FAILED"
    fig.suptitle(f"{title} execution in MuJoCo ({report['mode']}): {verdict}".strip())
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
