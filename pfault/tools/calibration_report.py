"""What ``python -m pfault.calibrate`` writes in its output directory (all CSV in SI units, times in s):

- ``parameters.csv``: name, option, start, fitted, standard_error (first-order, in the option's unit),
  standard_error_log10 (log parameters), lower_2se, upper_2se (fitted -/+ 2 standard errors in the fitted
  variable: a factor 10^(2 se) for log parameters), lower, upper, transform, at_bound, identifiable; a parameter
  the observations do not pin down within its bounds (pfault.tools.calibration.identifiable) has identifiable
  false and its fitted value and band empty (its standard error, inf or larger than its bounds' span, stays);
- ``correlation.csv``: the parameters' correlation matrix at the optimum;
- ``residuals.csv``: per station, time and component: observed, simulated, sigma, residual (simulated -
  observed) and weighted residual, for the fitted run;
- ``runs.csv``: every forward run: number, purpose (start, trial, jacobian, fitted), the parameter values,
  phi, wall time, exit code and the run's one-line error when it failed; ``runs/NNNN.log`` its output;
- ``fitted/``: the output directory of the run at the fitted values; ``fitted.opts``: the scene with the
  fitted values (``python -m pfault fitted.opts`` runs it again);
- ``observed_vs_simulated.png``: each station's observed components (error bars: sigma) and the simulated
  series at the start and at the fit;
- ``calibration.json``: the summary (phi at the start and the fit, degrees of freedom, residual variance,
  iterations, runs, the optimiser's message, per-station RMS of the weighted residuals; per parameter its value
  and standard errors, or for a parameter not identifiable ``value`` null, ``identifiable`` false and
  ``held_at``, the value the fitted run used; ``not_identifiable`` lists them). Non-finite numbers are null.
"""

from __future__ import annotations

import csv
import json
import os
import shutil

import numpy as np

from ..post.rundir import read_station_series
from .calibration import Fit, Problem
from .calibration_input import COMPONENTS, scene_files_absolute
from .insar_report import write_insar_outputs


def write_all(out: str, problem: Problem, result: Fit, scene: str, wall: float) -> None:
    _parameters(out, problem, result)
    _correlation(out, problem, result)
    _residuals(out, problem, result)
    write_runs(out, problem)
    fitted = os.path.join(out, "fitted")
    shutil.move(result.evaluation.result.run.output_dir, fitted)
    _fitted_options(out, problem, result, scene)
    if len(problem.observations.value):
        _figure(out, problem, fitted)
    if problem.insar is not None:
        write_insar_outputs(out, problem.insar, fitted)
    _summary(out, problem, result, scene, wall)


def _parameters(out, problem, r):
    with open(os.path.join(out, "parameters.csv"), "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "option", "start", "fitted", "standard_error", "standard_error_log10", "lower_2se",
                    "upper_2se", "lower", "upper", "transform", "at_bound", "identifiable"])
        for k, p in enumerate(problem.parameters):
            ok = bool(r.identifiable[k])
            band = [f"{problem.to_values(r.x + s * r.se_x)[k]:.6g}" if ok else "" for s in (-2, 2)]
            w.writerow([p.name, "-" + p.option, repr(p.start), repr(float(r.values[k])) if ok else "",
                        f"{r.se_value[k]:.6g}", f"{r.se_x[k]:.6g}" if p.log else "", *band, repr(p.lower),
                        repr(p.upper), "log" if p.log else "none", str(bool(r.at_bound[k])).lower(), str(ok).lower()])


def _correlation(out, problem, r):
    names = [p.name for p in problem.parameters]
    with open(os.path.join(out, "correlation.csv"), "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", *names])
        for name, row in zip(names, r.correlation):
            w.writerow([name, *(f"{c:.6f}" if np.isfinite(c) else "" for c in row)])


def _residuals(out, problem, r):
    obs = problem.observations
    sim = problem.simulated(r.evaluation.result.run.output_dir)
    with open(os.path.join(out, "residuals.csv"), "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "time_s", "component", "observed_m", "simulated_m", "sigma_m", "residual_m",
                    "weighted_residual"])
        for i in range(len(obs.value)):
            w.writerow([obs.station[i], repr(float(obs.time[i])), COMPONENTS[obs.component[i]],
                        repr(float(obs.value[i])), repr(float(sim[i])), repr(float(obs.sigma[i])),
                        f"{sim[i] - obs.value[i]:.6g}", f"{(sim[i] - obs.value[i]) / obs.sigma[i]:.6g}"])


def write_runs(out: str, problem: Problem) -> None:
    """runs.csv (written again after every batch of runs, so that a stopped fit leaves its log)."""
    with open(os.path.join(out, "runs.csv"), "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["run", "purpose", *(p.name for p in problem.parameters), "phi", "wall_s", "exit_code",
                    "error"])
        for ev in problem.evaluations:
            w.writerow([ev.number, ev.purpose, *(repr(float(v)) for v in ev.values),
                        f"{ev.phi:.8g}" if np.isfinite(ev.phi) else "", f"{ev.result.wall:.2f}", ev.result.code,
                        ev.result.error or ""])


def _fitted_options(out, problem, r, scene):
    lines = [f"# {scene} with the values fitted by python -m pfault.calibrate (calibration.json)",
             "# run it from the directory the calibration ran from (the scene's relative paths hold there)",
             f"-options_file {os.path.abspath(scene)}"]
    fitted = {p.option for p in problem.parameters}
    files = {k: v for k, v in scene_files_absolute(scene).items() if k not in fitted}
    if files:
        lines.append("# the scene's data files, found from anywhere")
        lines += [f"-{name} {value}" for name, value in files.items()]
    lines.append("# the fitted values")
    for p, v, ok in zip(problem.parameters, r.values, r.identifiable):
        if not ok:
            lines.append(f"# {p.name} is not identifiable from the observations: held at its value of the fit")
        lines.append(f"-{p.option} {p.option_value(v)}")
    with open(os.path.join(out, "fitted.opts"), "w") as fh:
        fh.write("\n".join(lines) + "\n")


def _figure(out, problem, fitted_dir):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    obs = problem.observations
    names = obs.stations
    fit = read_station_series(fitted_dir)
    start_ev = problem.evaluations[0]
    start = read_station_series(start_ev.result.run.output_dir) if start_ev.result.ok else None
    cols = min(3, len(names))
    rows = -(-len(names) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    colours = ("tab:blue", "tab:orange", "tab:green")
    for ax, name in zip(axes.flat, names):
        here = obs.station == name
        day = 86400.0
        for k in sorted(set(obs.component[here].tolist())):
            sel = here & (obs.component == k)
            ax.errorbar(obs.time[sel] / day, obs.value[sel] * 1e3, yerr=obs.sigma[sel] * 1e3, fmt="o", ms=3,
                        color=colours[k], label=f"{COMPONENTS[k]} observed")
            ax.plot(fit[name].time / day, fit[name].u[:, k] * 1e3, "-", color=colours[k],
                    label=f"{COMPONENTS[k]} fitted")
            if start is not None:
                ax.plot(start[name].time / day, start[name].u[:, k] * 1e3, ":", color=colours[k],
                        label=f"{COMPONENTS[k]} start")
        ax.set_title(name)
        ax.set_xlabel("time (day)")
        ax.set_ylabel("displacement (mm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "observed_vs_simulated.png"), dpi=110)
    plt.close(fig)


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _fitted(p, value, se, se_x, at_bound, ok) -> dict:
    """calibration.json's entry of a parameter: its value and standard errors, or null and the value it was held
    at when the observations do not pin it down."""
    out = {"option": "-" + p.option, "value": float(value) if ok else None, "identifiable": bool(ok),
           "standard_error": _finite(se), **({"standard_error_log10": _finite(se_x)} if p.log else {}),
           "at_bound": bool(at_bound)}
    if not ok:
        out["held_at"] = float(value)
    return out


def _summary(out, problem, r, scene, wall):
    obs = problem.observations
    w = r.evaluation.residual[:len(obs.value)]
    per_station = {name: float(np.sqrt(np.mean(w[obs.station == name] ** 2))) for name in obs.stations}
    summary = {
        "scene": scene, "converged": r.converged, "message": r.message, "iterations": r.iterations,
        "runs": len(problem.evaluations), "failed_runs": sum(not ev.result.ok for ev in problem.evaluations),
        "wall_s": wall, "observations": int(len(obs.value)), "parameters": len(problem.parameters),
        "degrees_of_freedom": r.dof, "phi_start": r.phi_start, "phi": r.phi, "residual_variance": r.variance,
        "fitted": {p.name: _fitted(p, v, se, sx, b, ok) for p, v, se, sx, b, ok
                   in zip(problem.parameters, r.values, r.se_value, r.se_x, r.at_bound, r.identifiable)},
        "not_identifiable": [p.name for p, ok in zip(problem.parameters, r.identifiable) if not ok],
        "correlation": [[_finite(c) for c in row] for row in r.correlation],
        "rms_weighted_residual_per_station": per_station,
        "fitted_run": "fitted", "fitted_options": "fitted.opts",
    }
    if problem.insar is not None:
        wi = r.evaluation.residual[len(obs.value):]
        summary["insar"] = {**problem.insar.summary(), "rms_weighted_residual": float(np.sqrt(np.mean(wi ** 2)))}
    with open(os.path.join(out, "calibration.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
