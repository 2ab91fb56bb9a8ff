"""Accuracy against cost: error, unknowns, wall time and iterations of pfault on problems with a known answer.

    .venv/bin/python benchmarks/accuracy_cost.py [--quick] [--problems mms,theis,...] [--ranks 2]
        [--fault-solvers mumps,iterative] [--elastic-solvers mumps,gamg] [--rtols 1e-4,1e-6]
        [--penalty 0.1,1,10,100] [--out runs/accuracy_cost] [--report-only]

Problems (the error is relative, in the quantity named; ``h`` is the size measure the rates use):

- ``mms``: manufactured solution on the unit cube (tests/scripts/mms.py), L2 error of the displacement
  over its L2 norm (and the same for the H1 seminorm); h = 1/n.
- ``oedometer``: config/oedometer.opts, settlement against c_M alpha |dp| H; P1 holds the linear profile
  exactly, so the error is the linear solver's; h = column height / cells.
- ``theis``: transient drawdown of a pumped confined aquifer (tests/scripts/theis.py), largest relative error
  at 20-200 m from the well; 2n backward-Euler steps, so time and space are refined together; h = the
  smallest horizontal cell.
- ``penny``: penny-shaped crack under tension (config/penny_crack.opts, tests/scripts/penny_mesh.py),
  area-weighted RMS error of the face openings against Sneddon over the opening at the centre w0; h = a/n.
  The domain of 8 crack radii adds about +0.45 % to the opening, a floor the mesh cannot remove.
- ``two_blocks``: config/two_blocks.opts in the slip state, largest error of the fault's jump vector (opening,
  slip) against (0, delta - L tau_L / G), over the exact slip; Lagrange faces hold it to round-off on every
  mesh, penalty faces err by their penetration p/k; h = sqrt(median fault face area).
- ``wuxi``, ``queretaro``: config/wuxi.opts (largest fissure opening) and config/queretaro_calibrated.opts
  (largest fault slip) against the finest mesh of the ladder (-pfault_mesh_size_factor); h = size factor. Their
  other values (opening, slip, subsidence) relative to the reference's, or in metres where the reference's value is
  zero in exact arithmetic (``case_errors``).

Axes: the mesh ladder of every problem; the solvers (a direct and an iterative one: ``--fault-solvers`` for
fault scenes, ``--elastic-solvers`` for the fault-free ones; names of pfault's solver files); the nonlinear
tolerance (-snes_rtol, ``--rtols`` next to the code default 1e-10) on the fault problems; penalty faces at
multiples of E/h (``--penalty``: E the harmonic mean of the two sides' moduli, h = sqrt of the median
fault face area of the Lagrange run on the same mesh) against the Lagrange multipliers.

``--quick`` runs every problem and axis on the smallest meshes, on 1 rank (QUICK below): what the test suite runs.

Runs one MPI job at a time and writes ``OUT/report.md`` (one table per problem, the cheapest setting for
10 %, 5 % and 1 % error, the observed rates, the case studies' effects and their cost), ``OUT/error_vs_time.png``
(log-log, one curve per solver or method) and ``OUT/results.json``; each run keeps its output and log under
``OUT/<problem>/<run>/``. Wall times are end to end (mpirun, imports, meshing, solve, output without the PNG
figures), with the 1-minute load average during the run. The exit code is 1 if a run fails (exit code,
divergence, unreadable output, or no error to measure), else 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from pfault.post.rundir import read_summary

from pfault.tools.runs import cpu_model, run_logged

from . import REPO

SCRIPTS = os.path.join(REPO, "tests", "scripts")
LEVELS = (0.10, 0.05, 0.01)             # error levels of the "cheapest setting" table
DEFAULT_RTOL = 1e-10                    # pfault's -snes_rtol default
TIMEOUT = 3600.0
PROBLEMS = ("mms", "oedometer", "theis", "penny", "two_blocks", "wuxi", "queretaro")

# The ladders. Levels: n (mms, theis, penny, two_blocks), cells per 10 m of column (oedometer), size factor
# (case studies; the last one is the reference). tol_levels/penalty_levels: the levels that get the
# tolerance and penalty runs; iterative_levels: the levels the second solver (iterative, or MUMPS for Theis) runs
# (all when absent); options: options added to every run of the problem.
# QUICK is what the test suite runs (tests/verification/test_accuracy_cost.py): every problem and every axis, on
# the smallest meshes that still give each series' rate (2-3 levels of the first solver) and the other axes at one
# or two levels; the case studies at size factors 8 and 6 with the 10 years in 2 steps; on 1 rank. 26 runs, 28 CPU
# seconds (docs/performance.md).
QUICK = {
    "mms": {"levels": (4, 6, 8), "iterative_levels": (4,)},
    "oedometer": {"levels": (1, 2), "iterative_levels": (1,)},
    "theis": {"levels": (12, 24), "iterative_levels": (12,)},
    "penny": {"levels": (4, 6), "tol_levels": (4,), "iterative_levels": (4,)},
    "two_blocks": {"levels": (2, 4), "tol_levels": (2,), "iterative_levels": (2,), "penalty_levels": (2, 4)},
    "wuxi": {"levels": (8, 6), "iterative_levels": (), "options": ("-pfault_time_steps", "2")},
    "queretaro": {"levels": (8, 6), "iterative_levels": (), "penalty_levels": (),
                  "options": ("-pfault_time_steps", "2")},
}
FULL = {
    "mms": {"levels": (4, 8, 12, 16, 24)},
    "oedometer": {"levels": (1, 2, 4, 8)},
    "theis": {"levels": (12, 24, 48, 96)},
    "penny": {"levels": (4, 6, 8, 10), "tol_levels": (8,)},
    "two_blocks": {"levels": (2, 4, 6, 8, 12), "tol_levels": (4, 8), "penalty_levels": (2, 4, 6, 8, 12)},
    "wuxi": {"levels": (4, 3, 2, 1.5, 1), "tol_levels": (2,), "iterative_levels": (4, 3)},
    "queretaro": {"levels": (4, 3, 2, 1.5, 1), "tol_levels": (2,), "iterative_levels": (4, 3),
                  "penalty_levels": (3, 2)},
}


@dataclass
class Row:
    """One run: where it sits on the axes, its error and what it cost."""
    problem: str
    series: str                 # the curve: solver or method (and tolerance)
    level: float                # ladder value (n, cells, size factor)
    h: float                    # size measure of the rates
    unknowns: int
    error: float | None         # relative error of the problem's quantity
    extra: dict = field(default_factory=dict)   # other errors and values
    wall_s: float = float("nan")
    newton: int | None = None
    krylov: int | None = None
    lu: int | None = None
    ok: bool = True
    note: str = ""
    load: float = float("nan")
    command: str = ""
    reference: bool = False
    effects: dict = field(default_factory=dict)     # a pfault run's summary.json "effects", steps and solve time


@dataclass(frozen=True)
class Study:
    """Settings shared by every problem."""
    out: str
    ranks: int = 2
    fault_solvers: tuple = ("mumps", "iterative")
    elastic_solvers: tuple = ("mumps", "gamg")
    rtols: tuple = (1e-4, 1e-6)
    penalty: tuple = (1.0, 100.0)
    timeout: float = TIMEOUT


# ------------------------------------------------------------------------------------------------------
# running
# ------------------------------------------------------------------------------------------------------
def run_command(args, rundir, ranks, timeout=TIMEOUT):
    """Runs ``python ARGS`` (under mpirun for ranks > 1) from the repository root, logging to rundir/stdout.txt."""
    return run_logged(args, ranks, os.path.join(rundir, "stdout.txt"), timeout, cwd=REPO)


def run_pfault(study, problem, name, scene, extra=()):
    """One pfault run; returns (Done, summary or None, output directory)."""
    rundir = os.path.join(study.out, problem, name)
    path = os.path.join(rundir, "summary.json")
    if os.path.exists(path):
        os.remove(path)
    # no PNG figures: drawing them is output, not the cost of an answer (seconds a run, more than a small solve)
    done = run_command(["-m", "pfault", scene, "-pfault_output_dir", rundir, "-pfault_figures", "false", *extra],
                       rundir, study.ranks, study.timeout)
    summary = read_summary(rundir)
    print(f"accuracy: {problem}/{name}: exit {done.code}, {done.wall:.1f} s (load {done.load:.1f})", flush=True)
    return done, summary, rundir


def counts(summary):
    """Newton, Krylov iterations and factorisations summed over the steps."""
    steps = summary["steps"]
    return (sum(int(s.get("newton_its", 0)) for s in steps), sum(int(s.get("ksp_its", 0)) for s in steps),
            sum(int(s.get("factorizations", 0) or 0) for s in steps))


def pfault_row(problem, series, level, h, done, summary, error_fn):
    """A Row from a pfault run; error_fn(summary) -> (error, extra) is called only on a converged run."""
    row = Row(problem, series, level, h, 0, None, wall_s=done.wall, load=done.load, command=done.command)
    if summary is not None:
        row.unknowns = int(summary.get("dofs", 0))
        row.newton, row.krylov, row.lu = counts(summary)
        row.effects = {"effects": summary.get("effects", {}), "solve_s": summary.get("wall_s", {}).get("solve"),
                       "steps": len([r for r in summary["steps"] if not r.get("initial")])}
    if done.code != 0 or summary is None or not summary.get("converged", False):
        row.ok = False
        row.note = f"exit code {done.code}" + ("" if summary is None else
                                                f", converged {summary.get('converged')}")
        return row
    try:
        row.error, row.extra = error_fn(summary)
    except (OSError, KeyError, ValueError) as exc:       # unreadable output is a failed run
        row.ok, row.note = False, f"no error measured: {exc}"
    return row


def solver_args(solver):
    return [] if solver == "mumps" else ["-pfault_solver", solver]


def rtol_series(base, rtol):
    return f"{base}, rtol {rtol:g}"


# ------------------------------------------------------------------------------------------------------
# problems without faults
# ------------------------------------------------------------------------------------------------------
def mms_worker(argv):
    """In the MPI job: solve tests/scripts/mms.py at n = argv[0] with the PETSc options that follow; print JSON
    with the L2 and H1 errors relative to the L2 norm and H1 seminorm of the manufactured displacement
    c sin(pi x) sin(pi y) sin(pi z) on the unit cube: |c| / sqrt(8) and |c| pi sqrt(3/8)."""
    import petsc4py
    petsc4py.init([sys.argv[0], *argv[1:], "-ksp_converged_reason"])
    sys.path.insert(0, SCRIPTS)
    import mms  # noqa: E402  (its own petsc4py.init is a no-op now)
    from petsc4py import PETSc
    n = int(argv[0])
    c = float(np.linalg.norm(mms.C))
    l2, h1 = mms.solve(n)
    if PETSc.COMM_WORLD.rank == 0:
        print(json.dumps({"n": n, "l2": l2 / (c / math.sqrt(8.0)), "h1": h1 / (c * math.pi * math.sqrt(3.0 / 8.0))}),
              flush=True)


def elastic_solver_options(solver):
    """PETSc options for a script that builds its own KSP: pfault's solver file (package data; found here
    without importing pfault.solver.setup, which would start PETSc in this driver), and preonly for LU."""
    opts = ["-options_file", str(resources.files("pfault.solver").joinpath("options", f"{solver}.opts"))]
    return opts + (["-ksp_type", "preonly"] if solver == "mumps" else [])


def solver_levels(solvers, ladder):
    """(solver, level) pairs: the first solver on every level of the ladder, the others on its iterative_levels
    (every level when absent)."""
    return [(solver, level) for i, solver in enumerate(solvers) for level in ladder["levels"]
            if i == 0 or level in ladder.get("iterative_levels", ladder["levels"])]


def study_mms(study, ladder):
    rows = []
    for solver, n in solver_levels(study.elastic_solvers, ladder):
        rundir = os.path.join(study.out, "mms", f"{solver}-n{n}")
        done = run_command(["-m", "studies.accuracy", "mms-worker", n, *elastic_solver_options(solver)],
                           rundir, study.ranks, study.timeout)
        print(f"accuracy: mms/{solver}-n{n}: exit {done.code}, {done.wall:.1f} s (load {done.load:.1f})",
              flush=True)
        row = Row("mms", solver, n, 1.0 / n, 3 * (n + 1) ** 3, None, wall_s=done.wall, load=done.load,
                  command=done.command)
        its = [int(m) for m in re.findall(r"Linear solve converged due to \S+ iterations (\d+)", done.output)]
        found = [json.loads(s) for s in done.output.splitlines() if s.startswith("{")]
        if done.code != 0 or not found or not its:
            row.ok, row.note = False, f"exit code {done.code}" + ("" if its else ", linear solve not converged")
        else:
            row.error, row.extra = found[-1]["l2"], {"H1 error": found[-1]["h1"]}
            row.krylov = its[-1]
        rows.append(row)
    return rows


def study_oedometer(study, ladder):
    """Column 10 x 10 x 100 m with k x k x 10k cells."""
    young, nu, dp, height = 10e6, 0.25, 0.1e6, 100.0
    exact = (1 + nu) * (1 - 2 * nu) / (young * (1 - nu)) * dp * height
    rows = []
    for solver, k in solver_levels(study.elastic_solvers, ladder):
        extra = ["-pfault_box_cells", f"{k},{k},{10 * k}", *solver_args(solver)]
        done, summary, _ = run_pfault(study, "oedometer", f"{solver}-k{k}", "config/oedometer.opts", extra)

        def error(s):
            return abs(s["max_subsidence_m"] - exact) / exact, {"settlement m": s["max_subsidence_m"]}
        rows.append(pfault_row("oedometer", solver, k, height / (10 * k), done, summary, error))
    return rows


THEIS_SOLVERS = {"cg+hypre": [], "mumps": ["-flow_ksp_type", "gmres", "-flow_pc_type", "lu",
                                           "-flow_pc_factor_mat_solver_type", "mumps"]}


def study_theis(study, ladder):
    rows = []
    for solver, n in solver_levels(list(THEIS_SOLVERS), ladder):
        opts = THEIS_SOLVERS[solver]
        rundir = os.path.join(study.out, "theis", f"{solver}-n{n}")
        done = run_command([os.path.join(SCRIPTS, "theis.py"), n, *opts], rundir, study.ranks, study.timeout)
        print(f"accuracy: theis/{solver}-n{n}: exit {done.code}, {done.wall:.1f} s (load {done.load:.1f})",
              flush=True)
        row = Row("theis", solver, n, float("nan"), 2 * (n + 1) ** 2, None, wall_s=done.wall, load=done.load,
                  command=done.command)
        found = [json.loads(s) for s in done.output.splitlines() if s.startswith("{")]
        if done.code != 0 or not found:
            row.ok, row.note = False, f"exit code {done.code}"
        else:
            r = found[-1]
            row.h, row.error, row.krylov = r["h_min"][0], r["max_rel_err"][0], r["ksp_its"][0]
            row.extra = {"error at 100 m": r["rel_err_at"][0][2]}
        rows.append(row)
    return rows


# ------------------------------------------------------------------------------------------------------
# fault problems with an analytic answer
# ------------------------------------------------------------------------------------------------------
def fault_series(study, ladder, level):
    """(series, extra options) of one mesh level: the solvers (the iterative ones on iterative_levels), then
    the tolerances of tol_levels with the first (direct) solver."""
    out = []
    for i, solver in enumerate(study.fault_solvers):
        if i == 0 or level in ladder.get("iterative_levels", ladder["levels"]):
            out.append((solver, solver_args(solver)))
    if level in ladder.get("tol_levels", ()):
        base = study.fault_solvers[0]
        out += [(rtol_series(base, r), [*solver_args(base), "-snes_rtol", f"{r:g}"]) for r in study.rtols]
    return out


def study_penny(study, ladder):
    sys.path.insert(0, SCRIPTS)
    from penny_mesh import crack_errors, make_penny_mesh
    rows = []
    for n in ladder["levels"]:
        mesh = os.path.join(study.out, "penny", f"penny{n}.msh")
        os.makedirs(os.path.dirname(mesh), exist_ok=True)
        t0 = time.perf_counter()
        make_penny_mesh(mesh, 1.0, 8.0, n)
        mesh_s = time.perf_counter() - t0
        for series, extra in fault_series(study, ladder, n):
            name = f"{series.replace(', rtol ', '-rtol')}-n{n}"
            done, summary, rundir = run_pfault(study, "penny", name, "config/penny_crack.opts",
                                               ["-pfault_mesh_file", mesh, *extra])

            def error(s, rundir=rundir):
                e = crack_errors(rundir)
                return e["rms_error"], {"max error": abs(e["max_error"]), "centre error": abs(e["centre_error"])}
            row = pfault_row("penny", series, n, 1.0 / n, done, summary, error)
            row.extra["mesh s"] = mesh_s
            rows.append(row)
    return rows


TB = {"E": 10e6, "nu": 0.25, "p": 1e6, "phi": 30.0, "L": 2.0, "delta": 0.5}


def two_blocks_exact_slip():
    g = TB["E"] / (2 * (1 + TB["nu"]))
    return TB["delta"] - TB["L"] * TB["p"] * math.tan(math.radians(TB["phi"])) / g


def fault_faces(rundir):
    """Areas of the fault faces and the last step's fault fields (serial face order)."""
    sys.path.insert(0, SCRIPTS)
    from penny_mesh import read_fault_step
    points, tri, data = read_fault_step(rundir)
    x = points[tri]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    return area, data


def two_blocks_error(rundir):
    exact = two_blocks_exact_slip()
    _, f = fault_faces(rundir)
    slip = np.asarray(f["slip"], float)
    jump_err = np.sqrt(np.asarray(f["opening"], float) ** 2 + slip[:, 0] ** 2 + slip[:, 1] ** 2
                       + (slip[:, 2] - exact) ** 2)
    return float(jump_err.max() / exact), {"slip m": float(np.max(f["slip_magnitude"])),
                                           "opening m": float(np.min(f["opening"]))}


def penalty_args(fault, k):
    return [f"-pfault_fault_{fault}_method", "penalty", f"-pfault_fault_{fault}_penalty_normal", f"{k:.6g}",
            f"-pfault_fault_{fault}_penalty_tangential", f"{k:.6g}"]


def penalty_series(m):
    return f"penalty {m:g} E/h"


def study_two_blocks(study, ladder):
    """Slip state of config/two_blocks.opts on (2n, n, n) cells."""
    rows = []
    for n in ladder["levels"]:
        mesh = ["-pfault_box_cells", f"{2 * n},{n},{n}"]
        h = None
        for series, extra in fault_series(study, ladder, n):
            name = f"{series.replace(', rtol ', '-rtol')}-n{n}"
            done, summary, rundir = run_pfault(study, "two_blocks", name, "config/two_blocks.opts", [*mesh, *extra])
            if h is None and done.code == 0:
                h = float(np.sqrt(np.median(fault_faces(rundir)[0])))
            rows.append(pfault_row("two_blocks", series, n, h or float("nan"), done, summary,
                                   lambda s, d=rundir: two_blocks_error(d)))
        if n in ladder.get("penalty_levels", ()) and h is not None:
            for m in study.penalty:
                k = m * TB["E"] / h
                done, summary, rundir = run_pfault(study, "two_blocks", f"penalty{m:g}-n{n}", "config/two_blocks.opts",
                                                   [*mesh, *penalty_args("fault", k)])
                row = pfault_row("two_blocks", penalty_series(m), n, h, done, summary,
                                 lambda s, d=rundir: two_blocks_error(d))
                row.extra["k Pa/m"] = k
                rows.append(row)
    return rows


# ------------------------------------------------------------------------------------------------------
# case studies against their finest mesh
# ------------------------------------------------------------------------------------------------------
CASES = {
    # scene, fault name, the quantity of the error, harmonic mean of the two sides' Young's moduli at the fault
    "wuxi": ("config/wuxi.opts", "fissure", "max_fault_opening_m", 2 / (1 / 8e6 + 1 / 1200e6)),
    "queretaro": ("config/queretaro_calibrated.opts", "fault", "max_fault_slip_m", 2 / (1 / 15e6 + 1 / 4900e6)),
}
CASE_VALUES = {"max_fault_opening_m": "opening", "max_fault_slip_m": "slip", "max_subsidence_m": "subsidence"}
# A case's opening, slip and subsidence are computed from its displacement field; a reference value below this share
# of the reference's largest displacement is zero in exact arithmetic (no face open, none slid: pfault reports 0, or
# the solver's tolerance, -snes_rtol 1e-10 by default), and an error relative to it would mean nothing.
ZERO_SHARE = 1e-9


def displacement_scale(summary):
    """The largest displacement of a run (m): the scale its jumps and subsidence are computed from."""
    return max(summary["max_subsidence_m"], summary["max_horizontal_displacement_m"])


def is_zero(summary, key):
    """Whether a run's value ``key`` is zero in exact arithmetic (ZERO_SHARE of its displacement scale)."""
    return abs(summary[key]) <= ZERO_SHARE * displacement_scale(summary)


def case_errors(s, ref):
    """Each value of CASE_VALUES of run ``s`` against the reference run ``ref``: '<value> error', the relative
    error, where the reference's value is not zero; '<value> difference m', the absolute difference in metres,
    where it is (calibrated Queretaro opens no face); and '<value> m', the value itself."""
    out = {}
    for q, v in CASE_VALUES.items():
        if is_zero(ref, q):
            out[f"{v} difference m"] = abs(s[q] - ref[q])
        else:
            out[f"{v} error"] = abs(s[q] / ref[q] - 1.0)
    out.update({f"{v} m": s[q] for q, v in CASE_VALUES.items()})
    return out


def case_runs(study, problem, ladder):
    """Every run of a case study: (series, factor, Done, summary, rundir); the reference (last level, direct
    solver) first."""
    scene, fault, _, young = CASES[problem]
    levels = list(ladder["levels"])
    order = [levels[-1]] + levels[:-1]
    runs, h_face = [], {}
    for f in order:
        size = ["-pfault_mesh_size_factor", f"{f:g}", *ladder.get("options", ())]
        for series, extra in fault_series(study, ladder, f):
            name = f"{series.replace(', rtol ', '-rtol')}-f{f:g}"
            done, summary, rundir = run_pfault(study, problem, name, scene, [*size, *extra])
            runs.append((series, f, done, summary, rundir))
            if f not in h_face and done.code == 0:
                h_face[f] = float(np.sqrt(np.median(fault_faces(rundir)[0])))
        if f in ladder.get("penalty_levels", ()) and f in h_face:
            for m in study.penalty:
                k = m * young / h_face[f]
                done, summary, rundir = run_pfault(study, problem, f"penalty{m:g}-f{f:g}", scene,
                                                   [*size, *penalty_args(fault, k)])
                runs.append((penalty_series(m), f, done, summary, rundir))
    return runs


def study_case(study, ladder, problem):
    quantity = CASES[problem][2]
    runs = case_runs(study, problem, ladder)
    ref = runs[0][3] if runs[0][2].code == 0 and runs[0][3] and runs[0][3].get("converged") else None
    # the default-tolerance run of the direct solver on each mesh, for the tolerance runs' own change
    base = {f: s for series, f, _, s, _ in runs if series == study.fault_solvers[0] and s}
    rows = []
    for i, (series, f, done, summary, _) in enumerate(runs):
        def error(s, f=f, series=series):
            if ref is None:
                raise ValueError("the reference run failed")
            if is_zero(ref, quantity):      # the case's error measure needs a value to be relative to
                raise ValueError(f"the reference's {quantity} is zero: no relative error")
            extra = case_errors(s, ref)
            if ", rtol " in series and f in base and not is_zero(base[f], quantity):
                extra[f"vs rtol {DEFAULT_RTOL:g}"] = abs(s[quantity] / base[f][quantity] - 1.0)
            return abs(s[quantity] / ref[quantity] - 1.0), extra
        row = pfault_row(problem, series, f, f, done, summary, error)
        row.reference = i == 0
        rows.append(row)
    return rows


def study_problem(study, name, ladder):
    if name in CASES:
        return study_case(study, ladder, name)
    return {"mms": study_mms, "oedometer": study_oedometer, "theis": study_theis, "penny": study_penny,
            "two_blocks": study_two_blocks}[name](study, ladder)


# ------------------------------------------------------------------------------------------------------
# analysis
# ------------------------------------------------------------------------------------------------------
def mesh_series(rows, series, key=None):
    """Converged, non-reference rows of one series with a positive error, coarse to fine."""
    get = (lambda r: r.error) if key is None else (lambda r: r.extra.get(key))
    sel = [r for r in rows if r.series == series and r.ok and not r.reference and (get(r) or 0) > 0
           and np.isfinite(r.h)]
    return sorted(sel, key=lambda r: -r.h), get


def observed_rates(rows, series, key=None, floor=1e-9):
    """Rates log(e1/e2)/log(h1/h2) between consecutive levels, the least-squares slope of log e on log h, and
    the slope of log e on log wall time; levels whose error is at round-off (below floor) are left out."""
    sel, get = mesh_series(rows, series, key)
    sel = [r for r in sel if get(r) > floor]
    if len(sel) < 2:
        return None
    e = np.log([get(r) for r in sel])
    h = np.log([r.h for r in sel])
    t = np.log([r.wall_s for r in sel])
    pairs = [float((e[i] - e[i + 1]) / (h[i] - h[i + 1])) for i in range(len(sel) - 1)]
    fit = float(np.polyfit(h, e, 1)[0])
    time_slope = float(np.polyfit(t, e, 1)[0]) if np.ptp(t) > 0 else float("nan")
    return {"series": series, "key": key or "error", "levels": [r.level for r in sel], "pairs": pairs,
            "fit": fit, "time_slope": time_slope}


def cheapest(rows, level):
    """The converged, non-reference row of least wall time whose error is at most level (None if none)."""
    ok = [r for r in rows if r.ok and not r.reference and r.error is not None and r.error <= level]
    return min(ok, key=lambda r: r.wall_s) if ok else None


def series_of(rows):
    seen = []
    for r in rows:
        if r.series not in seen:
            seen.append(r.series)
    return seen


# ------------------------------------------------------------------------------------------------------
# report
# ------------------------------------------------------------------------------------------------------
CASE_COLUMNS = (" The opening, slip and subsidence columns: the value, and its relative error against the reference "
                "or, where the reference's value is zero (no face open, none slid), the difference in metres.")
ABOUT = {
    "mms": ("Manufactured solution (unit cube, fixed boundary)", "L2 error of the displacement / its L2 norm",
            "n", "h = 1/n; n^3 x 6 tetrahedra. P1 converges at rate 2 in L2 and 1 in H1."),
    "oedometer": ("Oedometer (config/oedometer.opts)", "settlement error / c_M alpha |dp| H", "k",
                  "k x k x 10k cells, h = 10 m / k. P1 holds the linear displacement exactly: the error is the "
                  "linear solver's (round-off with MUMPS, -ksp_rtol with CG + GAMG) and has no mesh rate."),
    "theis": ("Theis drawdown (tests/scripts/theis.py)", "largest relative drawdown error at 20-200 m", "n",
              "n x n graded cells, one layer; 2n backward-Euler steps to 1 day, so the mesh and the time step are "
              "refined together; h = the smallest cell (at the well). Flow solvers: the code default (CG + "
              "BoomerAMG) and MUMPS."),
    "penny": ("Penny-shaped crack under tension (Sneddon)", "RMS opening error / w0", "n",
              "Quarter model, element size a/n at the crack (a/(3n) at its tip), h = a/n; Lagrange faces. The "
              "domain of 8 crack radii adds about +0.45 % to the opening: the error cannot fall much below that. "
              "'mesh s' is gmsh's time, not in the wall time."),
    "two_blocks": ("Two blocks, slip state (config/two_blocks.opts)",
                   "largest error of the fault jump (opening, slip) / exact slip 0.2113 m", "n",
                   "(2n, n, n) cells, h = sqrt(median fault face area). Lagrange faces give the analytic slip on every "
                   "mesh (uniform state); penalty faces penetrate by p/k, so at k = m E/h their error is h/(10 m) m "
                   "over 0.211 m: rate 1 in h at a fixed multiple m."),
    "wuxi": ("Wuxi earth fissure (config/wuxi.opts)", "largest fissure opening against the finest mesh",
             "factor", "-pfault_mesh_size_factor; the finest factor of the ladder is the reference (error 0 by "
                       "construction, marked 'ref', not counted as a cheapest setting). Rates against the finest "
                       "mesh overstate the true rate at the level next to it. Penalty stiffnesses: E = 15.9 MPa "
                       "(harmonic mean of 8 and 1200 MPa)." + CASE_COLUMNS),
    "queretaro": ("Queretaro, calibrated pumping (config/queretaro_calibrated.opts)",
                  "largest fault slip against the finest mesh", "factor",
                  "-pfault_mesh_size_factor, with the groundwater-flow model; the finest factor is the reference. "
                  "Penalty stiffnesses are multiples of E/h with E = 29.9 MPa (harmonic mean of 15 and 4900 MPa)."
                  + CASE_COLUMNS),
}



def pct(v):
    if v is None or not np.isfinite(v):
        return "—"
    if v == 0:
        return "0"
    return f"{100 * v:.3g} %" if v >= 1e-5 else f"{100 * v:.1e} %"


def fmt_extra(key, v):
    if v is None:
        return "—"
    if key.endswith("error") or key.startswith("vs "):
        return pct(v)
    if key.endswith(" s"):
        return f"{v:.1f}"
    return f"{v:.4g}"


def fmt_count(v):
    return "—" if v is None else str(v)


def problem_table(rows):
    keys = []
    for r in rows:
        keys += [k for k in r.extra if k not in keys]
    name = ABOUT[rows[0].problem][2]
    head = ["setting", name, "h", "unknowns", "error", *keys, "wall s", "load", "Newton", "Krylov", "LU"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        err = "ref" if r.reference else (pct(r.error) if r.ok else f"FAILED ({r.note})")
        cells = [r.series, f"{r.level:g}", f"{r.h:.3g}", f"{r.unknowns:,}", err,
                 *[fmt_extra(k, r.extra.get(k)) for k in keys], f"{r.wall_s:.1f}", f"{r.load:.1f}",
                 fmt_count(r.newton), fmt_count(r.krylov), fmt_count(r.lu)]
        out.append("| " + " | ".join(cells) + " |")
    return out


def describe(r):
    return f"{r.series}, {ABOUT[r.problem][2]} {r.level:g}: {r.wall_s:.1f} s ({pct(r.error)})"


def cheapest_table(by_problem):
    out = ["| problem | error measure | " + " | ".join(f"≤ {100 * lv:g} %" for lv in LEVELS) + " |",
           "|---|---|" + "---|" * len(LEVELS)]
    for name, rows in by_problem.items():
        cells = []
        for lv in LEVELS:
            best = cheapest(rows, lv)
            if best is None:
                done = [r for r in rows if r.ok and not r.reference and r.error is not None]
                low = min(done, key=lambda r: r.error) if done else None
                best_txt = f"not reached (least: {describe(low)})" if low else "not reached"
                cells.append(best_txt)
            else:
                cells.append(describe(best))
        out.append(f"| {name} | {ABOUT[name][1]} | " + " | ".join(cells) + " |")
    return out


def all_rates(by_problem):
    rates = []
    for name, rows in by_problem.items():
        for s in series_of(rows):
            if ", rtol " in s:          # their error is the Newton tolerance's, not the mesh's
                continue
            for key in [None] + (["H1 error"] if name == "mms" else []) + (["max error"] if name == "penny" else []):
                r = observed_rates(rows, s, key)
                if r is not None:
                    rates.append({"problem": name, **r})
    return rates


def rates_table(rates):
    out = ["| problem | setting | quantity | levels | rate between levels | fit | error ~ time^-s, s = |",
           "|---|---|---|---|---|---|---|"]
    for r in rates:
        out.append(f"| {r['problem']} | {r['series']} | {r['key']} | {', '.join(f'{v:g}' for v in r['levels'])} | "
                   f"{', '.join(f'{v:.2f}' for v in r['pairs'])} | {r['fit']:.2f} | {-r['time_slope']:.2f} |")
    return out


def effects_rows(rows):
    """The case studies' converged runs at the solvers' default tolerance, with the effects record of their
    summary.json (pfault.effects: the set-up and per-step time of each effect its scene asks for)."""
    return [r for r in rows if r.problem in CASES and r.ok and r.effects.get("effects")
            and ", rtol " not in r.series and not r.series.startswith("penalty")]


def effects_table(rows):
    """What each effect a case study asks for costs, next to the run's solve time: set-up / per step (s), 'off'
    for an effect the scene does not ask for (its fields, solvers and kernels are not built)."""
    sel = effects_rows(rows)
    names = [k for k in dict.fromkeys(k for r in sel for k in r.effects["effects"])
             if any(r.effects["effects"][k]["on"] for r in sel)]
    head = ["problem", "setting", "factor", "unknowns", "steps", "solve s",
            *[f"{k} set-up / per step s" for k in names], "effects' share of the solve"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in sel:
        eff = r.effects["effects"]
        cells = [f"{eff[k]['setup_s']:.3g} / {eff[k]['per_step_s']:.3g}" if eff[k]["on"] else "off" for k in names]
        share = sum(e["per_step_s"] for e in eff.values() if e["on"]) * r.effects["steps"] / r.effects["solve_s"]
        out.append("| " + " | ".join([r.problem, r.series, f"{r.level:g}", f"{r.unknowns:,}", str(r.effects["steps"]),
                                       f"{r.effects['solve_s']:.2f}", *cells, f"{100 * share:.3g} %"]) + " |")
    return out


def header(meta, rows):
    loads = [r.load for r in rows if np.isfinite(r.load)]
    failed = [r for r in rows if not r.ok]
    return [
        "# Accuracy against cost", "",
        f"Written by `{meta['command']}` at git {meta['git']} on {meta['date']}; {meta['ranks']} MPI ranks, one run "
        f"at a time; {meta['cpus']} cores ({meta['cpu']}), shared with other jobs. The 1-minute load average during "
        f"the runs was {min(loads):.1f} to {max(loads):.1f} (mean {np.mean(loads):.1f}); at 2.0 the two ranks had the "
        "machine to themselves, above it the wall times are inflated by about load/2. "
        f"Study run time {meta['study_s']:.0f} s, {len(rows)} runs, {len(failed)} failed.", "",
        "Wall time: end to end (mpirun, Python imports, meshing except the penny crack's gmsh mesh, solve, output "
        "without the PNG figures). "
        "Newton: iterations summed over the steps (each step's elastic trial counts as one); Krylov: linear "
        "iterations summed (1 per Newton iteration with MUMPS); LU: numerical factorisations. Errors are relative "
        "(a column named 'difference m' is an absolute difference in metres). "
        "Settings: the solver (`-pfault_solver`, MUMPS unless named), `rtol` = `-snes_rtol` (default 1e-10), "
        "`penalty m E/h` = penalty faces at m times E/h instead of Lagrange multipliers.", ""]


def write_report(path, rows, meta):
    by_problem = {}
    for r in rows:
        by_problem.setdefault(r.problem, []).append(r)
    rates = all_rates(by_problem)
    out = header(meta, rows)
    out += ["## Cheapest setting per error level", "",
            "The run of least wall time whose error is at most 10 %, 5 % and 1 % (any setting of the table below; "
            "the case studies' reference runs excluded).", ""]
    out += cheapest_table(by_problem)
    out += ["", "## Observed rates", "",
            "Rate between consecutive levels log(e1/e2)/log(h1/h2), least-squares slope of log e on log h, and s in "
            "error ~ (wall time)^-s. Errors at round-off (below 1e-9) and the tolerance ladders (their error is the "
            "Newton tolerance's, not the mesh's) are left out.", ""]
    out += rates_table(rates)
    out += ["", "![error against wall time](error_vs_time.png)", ""]
    if effects_rows(rows):
        out += ["## Effects and their cost", "",
                "The case studies' runs at the default tolerance: each effect's set-up time and time per step (the "
                "maximum over ranks of the PETSc events its work runs in: pfault.effects), and the per-step work "
                "of all of them over the steps' solve time (the rest is assembly and the linear solves of the "
                "displacement and multiplier system).", ""]
        out += effects_table(rows)
        out.append("")
    for name, prows in by_problem.items():
        title, measure, _, text = ABOUT[name]
        options = meta.get("ladders", {}).get(name, {}).get("options")
        if options:
            text += f" Every run of this study adds `{' '.join(options)}`."
        out += [f"## {title}", "", f"Error: {measure}. {text}", ""]
        out += problem_table(prows)
        out.append("")
    with open(path, "w") as fh:
        fh.write("\n".join(out))
    return rates


def write_figure(path, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(dict.fromkeys(r.problem for r in rows))
    ncol = min(4, len(names))
    nrow = (len(names) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.6 * nrow), squeeze=False)
    for ax, name in zip(axes.flat, names):
        prows = [r for r in rows if r.problem == name]
        for s in series_of(prows):
            sel = sorted((r for r in prows if r.series == s and r.ok and not r.reference and r.error is not None),
                         key=lambda r: r.wall_s)
            if sel:
                ax.loglog([r.wall_s for r in sel], [100 * max(r.error, 1e-14) for r in sel], "o-", ms=4, label=s)
        for lv in LEVELS:
            ax.axhline(100 * lv, color="0.7", lw=0.8, ls=":")
        ax.set_title(ABOUT[name][0], fontsize=8)
        ax.set_xlabel("wall time (s)", fontsize=8)
        ax.set_ylabel("error (%)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ------------------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------------------
def git_hash():
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                               capture_output=True, text=True).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "")
    except OSError:
        return "unknown"


def floats(text):
    return tuple(float(v) for v in text.split(",") if v)


def names(text):
    return tuple(v for v in text.split(",") if v)


def parse(argv):
    p = argparse.ArgumentParser(prog="benchmarks/accuracy_cost.py",
                                description="Accuracy against cost of pfault on problems with a known answer.")
    p.add_argument("--quick", action="store_true", help="every problem and axis on the smallest meshes, on 1 rank "
                   "(QUICK: 26 runs, about 30 s; what the test suite runs)")
    p.add_argument("--problems", type=names, default=PROBLEMS, help=f"comma list out of {','.join(PROBLEMS)}")
    p.add_argument("--ranks", type=int, default=None, help="MPI ranks of every run (default 2; 1 with --quick, whose "
                   "small runs MPI start-up and synchronisation would dominate)")
    p.add_argument("--fault-solvers", type=names, default=("mumps", "iterative"),
                   help="solvers of the fault scenes (-pfault_solver NAME); the first one also runs the "
                        "tolerance ladder")
    p.add_argument("--elastic-solvers", type=names, default=("mumps", "gamg"), help="solvers of fault-free scenes")
    p.add_argument("--rtols", type=floats, default=None, help="-snes_rtol values next to the default 1e-10")
    p.add_argument("--penalty", type=floats, default=None, help="penalty stiffnesses as multiples of E/h")
    p.add_argument("--out", default=os.path.join(REPO, "runs", "accuracy_cost"))
    p.add_argument("--report-only", action="store_true", help="rewrite report and figure from OUT/results.json")
    args = p.parse_args(argv)
    unknown = set(args.problems) - set(PROBLEMS)
    if unknown:
        p.error(f"unknown problems {sorted(unknown)}")
    if args.ranks is None:
        args.ranks = 1 if args.quick else 2
    if args.rtols is None:
        args.rtols = (1e-4,) if args.quick else (1e-4, 1e-6, 1e-8)
    if args.penalty is None:
        args.penalty = (1.0, 100.0) if args.quick else (0.1, 1.0, 10.0, 100.0, 1000.0)
    return args


def run_study(args, study):
    ladders = QUICK if args.quick else FULL
    path = os.path.join(study.out, "results.json")
    rows = []
    t0 = time.perf_counter()
    for name in args.problems:
        rows += study_problem(study, name, ladders[name])
        with open(path, "w") as fh:
            json.dump({"rows": [dataclasses.asdict(r) for r in rows]}, fh, indent=1)
    return rows, time.perf_counter() - t0


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["mms-worker"]:
        mms_worker(argv[1:])
        return 0
    args = parse(argv)
    study = Study(out=os.path.abspath(args.out), ranks=args.ranks, fault_solvers=args.fault_solvers,
                  elastic_solvers=args.elastic_solvers, rtols=args.rtols, penalty=args.penalty)
    os.makedirs(study.out, exist_ok=True)
    path = os.path.join(study.out, "results.json")
    if args.report_only:
        with open(path) as fh:
            saved = json.load(fh)
        rows, meta = [Row(**r) for r in saved["rows"]], saved["meta"]
    else:
        rows, elapsed = run_study(args, study)
        ladders = QUICK if args.quick else FULL
        meta = {"command": "benchmarks/accuracy_cost.py " + " ".join(argv), "git": git_hash(),
                "date": time.strftime("%Y-%m-%d %H:%M"), "ranks": study.ranks, "cpus": os.cpu_count(),
                "cpu": cpu_model(), "study_s": elapsed, "ladders": {k: ladders[k] for k in args.problems}}
        with open(path, "w") as fh:
            json.dump({"meta": meta, "rows": [dataclasses.asdict(r) for r in rows]}, fh, indent=1)
    rates = write_report(os.path.join(study.out, "report.md"), rows, meta)
    write_figure(os.path.join(study.out, "error_vs_time.png"), rows)
    with open(os.path.join(study.out, "rates.json"), "w") as fh:
        json.dump(rates, fh, indent=1)
    failed = [r for r in rows if not r.ok]
    for r in failed:
        print(f"accuracy: FAILED {r.problem} {r.series} {r.level:g}: {r.note}\n  {r.command}", flush=True)
    print(f"accuracy: {len(rows)} runs, {len(failed)} failed; report {os.path.join(study.out, 'report.md')}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
