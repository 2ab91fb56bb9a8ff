"""``python -m pfault.calibrate SCENE --parameters params.csv --observations obs.csv [--workers N]
[--output DIR]``: fits a few scalar options of a scene to station observations by weighted least squares.

Each forward model is a pfault run of SCENE with the parameters as command-line overrides (its own output
directory, figures off), up to --workers runs side by side. The file formats are in
pfault.tools.calibration_input, the method in pfault.tools.calibration, the outputs in
pfault.tools.calibration_report; README.md and docs/calibration.md have the walkthrough.

With --pest DIR it writes the problem as PEST/PEST++ files instead (pfault.tools.pest).

Exit codes: 0 fitted (calibration.json says whether the optimiser converged or stopped at
--max-iterations); 1 bad input (one line naming the file and the fix; nothing written); 2 usage; 3 a forward
run the fit cannot do without failed (its one-line error is printed; runs.csv and the runs' logs stay);
7 interrupted (the runs under way are stopped).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time

from .errors import EXIT_INPUT, EXIT_INTERRUPTED, EXIT_NOT_CONVERGED, EXIT_OK, InputError
from .georef import parse_date
from .tools.calibration import ForwardRunFailed, Problem, fit
from .tools.calibration_input import (CalibrationInputError, empty_observations, read_observations, read_parameters,
                                      scene_facts)
from .tools.calibration_report import write_all, write_runs
from .tools.insar_fit import InsarSettings, InsarTerm, parse_reference
from .tools.pest import write_pest
from .units import parse_quantity

PROG = "python -m pfault.calibrate"
MARKER = ".pfault_calibration"      # a directory written by a calibration, which the next one may replace


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description="Fit scalar -pfault_ options of a scene to station "
                                "displacement observations (weighted least squares, one pfault run per forward "
                                "model).")
    p.add_argument("scene", help="the scene (a pfault options file with -pfault_stations)")
    p.add_argument("--parameters", required=True, help="CSV: name,option,start,lower,upper[,transform][,value]")
    p.add_argument("--observations", help="CSV: name,time,ux,uy,uz,sigma (m, s; components may be empty)")
    p.add_argument("--insar", help="InSAR displacement time series (OPERA DISP-S1 NetCDF or MintPy timeseries.h5) "
                   "fitted at its pixels; the scene needs -pfault_start_date (and -pfault_crs for a product in a CRS)")
    p.add_argument("--insar-sigma", default="", help="standard deviation of an InSAR value (m, or with a unit: "
                   "5*mm); required with --insar")
    p.add_argument("--insar-reference", default="offset", help="'offset' (a constant per date, fitted; the "
                   "default) or x,y: the reference point in the product's CRS")
    p.add_argument("--workers", type=int, default=1, help="forward runs side by side (default 1)")
    p.add_argument("--ranks", type=int, default=1, help="MPI ranks of each forward run (default 1)")
    p.add_argument("--output", help="output directory (default runs/calibrate_<scene>)")
    p.add_argument("--max-iterations", type=int, default=20, help="most evaluations of the objective at new "
                   "points (each followed by a Jacobian of N parameters: N runs) (default 20)")
    p.add_argument("--timeout", type=float, help="s after which a forward run is stopped and counts as failed")
    p.add_argument("--pest", metavar="DIR", help="write the problem as PEST/PEST++ files into DIR (pfault.pst, "
                   "parameters.tpl, simulated.ins, ...) and stop, without fitting")
    p.add_argument("--keep-runs", action="store_true", help="keep every forward run's output directory (by "
                   "default only their logs, runs/NNNN.log, and the fitted run)")
    return p


def _fail(line: str, code: int) -> int:
    sys.stderr.write(f"pfault.calibrate: error: {line}\n")
    return code


def _check_output(out: str) -> str | None:
    if os.path.exists(out) and not os.path.isdir(out):
        return f"--output {out} is a file; give a directory"
    if os.path.isdir(out) and os.listdir(out) and not os.path.exists(os.path.join(out, MARKER)):
        return (f"--output {out} holds files a calibration did not write; give a new or empty directory "
                "(a calibration's own output directory is replaced)")
    return None


def _inputs(args):
    if not args.observations and not args.insar:
        raise CalibrationInputError("give --observations (station series) or --insar (an InSAR time series), or both")
    facts = scene_facts(args.scene, need_stations=bool(args.observations))
    params = read_parameters(args.parameters)
    obs = (read_observations(args.observations, facts.stations, facts.station_file, facts.time_end)
           if args.observations else empty_observations())
    return params, obs, _insar(args, facts) if args.insar else None


def _insar(args, facts):
    """The InSAR observations (pfault.tools.insar_fit), every InputError as a CalibrationInputError."""
    try:
        if not facts.start_date:
            raise InputError(f"--insar {args.insar}: the scene {args.scene} has no -pfault_start_date, so the "
                             "product's dates cannot be placed in the run; add it (the date of the scene's time 0)")
        if not args.insar_sigma:
            raise InputError("--insar-sigma: give the standard deviation of an InSAR value, e.g. 5*mm")
        sigma = parse_quantity(args.insar_sigma, "insar-sigma", "m")
        if not sigma > 0:
            raise InputError(f"--insar-sigma {args.insar_sigma}: must be > 0 (m)")
        settings = InsarSettings(args.insar, sigma, parse_reference(args.insar_reference))
        return InsarTerm(settings, parse_date(facts.start_date, "-pfault_start_date"), facts.time_end)
    except InputError as exc:
        raise CalibrationInputError(str(exc)) from None


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.workers < 1 or args.ranks < 1:
        return _fail("--workers and --ranks must be at least 1", EXIT_INPUT)
    try:
        params, obs, insar = _inputs(args)
    except CalibrationInputError as exc:
        return _fail(str(exc), EXIT_INPUT)
    measured = len(obs.value) + (insar.count() - insar.nuisance if insar is not None else 0)
    if measured <= len(params):
        what = f"observation file {args.observations}" if insar is None else "the observations"
        unit = "components" if insar is None else "values"
        return _fail(f"{what}: {measured} measured {unit} for {len(params)} parameters; give more observations "
                     "than parameters", EXIT_INPUT)
    if args.pest and insar is not None:
        return _fail("--pest with --insar: the PEST files hold station observations only; fit the InSAR series "
                     "with the built-in loop (without --pest)", EXIT_INPUT)
    if args.pest:
        return _write_pest(args, params, obs)
    out = args.output or os.path.join("runs", "calibrate_" + os.path.splitext(os.path.basename(args.scene))[0])
    problem_line = _check_output(out)
    if problem_line:
        return _fail(problem_line, EXIT_INPUT)
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(os.path.join(out, "runs"))
    open(os.path.join(out, MARKER), "w").close()

    def log(line):
        print(line, flush=True)
        write_runs(out, problem)

    problem = Problem(args.scene, params, obs, os.path.join(out, "runs"), args.workers, args.ranks, args.timeout,
                      log, insar=insar)
    more = f" and {insar.count()} InSAR values on {insar.dates} dates" if insar is not None else ""
    print(f"{PROG}: {len(params)} parameters, {len(obs.value)} measured components at "
          f"{len(obs.stations)} stations{more}; runs in {out}/runs, {args.workers} at a time", flush=True)
    t0 = time.perf_counter()
    try:
        result = fit(problem, args.max_iterations)
    except ForwardRunFailed as exc:
        write_runs(out, problem)
        return _fail(f"{exc}; every run is in {out}/runs.csv", EXIT_NOT_CONVERGED)
    except KeyboardInterrupt:
        write_runs(out, problem)
        return _fail(f"interrupted; the runs so far are in {out}/runs.csv", EXIT_INTERRUPTED)
    write_all(out, problem, result, args.scene, time.perf_counter() - t0)
    if not args.keep_runs:
        for ev in problem.evaluations:
            shutil.rmtree(ev.result.run.output_dir, ignore_errors=True)
    _print_result(problem, result, out)
    return EXIT_OK


def _write_pest(args, params, obs):
    if os.path.isdir(args.pest) and os.listdir(args.pest):
        return _fail(f"--pest {args.pest} is not empty; give a new or empty directory", EXIT_INPUT)
    os.makedirs(args.pest, exist_ok=True)
    write_pest(args.pest, args.scene, params, obs, args.max_iterations)
    print(f"{PROG}: PEST files in {args.pest}: pestpp-glm pfault.pst runs them (from that directory)")
    return EXIT_OK


def _print_result(problem, r, out):
    print(f"{PROG}: phi {r.phi_start:.6g} -> {r.phi:.6g} in {len(problem.evaluations)} runs "
          f"({r.dof} degrees of freedom, residual variance {r.variance:.4g}); {r.message}")
    lower, upper = problem.bounds()
    for p, v, se, sx, b, ok, lo, hi in zip(problem.parameters, r.values, r.se_value, r.se_x, r.at_bound,
                                           r.identifiable, lower, upper):
        if not ok:
            what = "log10 " if p.log else ""
            print(f"  {p.name:<12} NOT IDENTIFIABLE: the observations do not pin it within its bounds [{p.lower:.6g}, "
                  f"{p.upper:.6g}] (standard error of its {what}value {sx:.3g} against their span {hi - lo:.3g}); "
                  f"no fitted value (held at {v:.6g})")
            continue
        extra = f" (log10 se {sx:.4g}: a factor {10 ** sx:.4g})" if p.log else ""
        print(f"  {p.name:<12} {v:.6g} +/- {se:.3g}{extra}{'  AT A BOUND' if b else ''}")
    blind = [p.name for p, ok in zip(problem.parameters, r.identifiable) if not ok]
    if blind:
        print(f"{PROG}: {', '.join(blind)} not identifiable from these observations: no observation depends on "
              f"{'it' if len(blind) == 1 else 'them'} enough; fix {'it' if len(blind) == 1 else 'them'} from other "
              "data, or observe what depends on it (for a compression index Cc: heads below the preconsolidation "
              "head)")
    print(f"{PROG}: -> {out} (parameters.csv, residuals.csv, runs.csv, fitted/, fitted.opts, "
          "observed_vs_simulated.png)")


if __name__ == "__main__":
    sys.exit(main())
