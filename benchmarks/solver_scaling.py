#!/usr/bin/env python
"""Direct against iterative fault solver on the calibrated Queretaro scene at several mesh sizes, side by side.

    .venv/bin/python benchmarks/solver_scaling.py [--size-factors 2,1,0.5] [--solvers mumps,iterative]
                                                  [--ranks 2] [--out runs/solver_scaling] [-- more options]

For each size factor (1: the paper's mesh; 0.5: 8 times as many tetrahedra) it runs every solver in turn
(-pfault_solver NAME, all 10 years) under mpirun and prints one row per run: unknowns, Newton iterations,
Krylov iterations per Newton iteration (over the run and the largest of a step), set-up time (mesh and
assembly) and solve time, peak resident memory per rank, and the maxima of slip, opening and subsidence with
their relative difference from the first solver's. MUMPS is skipped below size factor 1 (it cannot factor
that system in 24 GiB here; --force runs it anyway). The rows go to OUT/results.json and, as a Markdown table,
to OUT/report.md.
"""
import argparse
import json
import os
import resource
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from pfault.post.rundir import read_summary  # noqa: E402
from pfault.tools.runs import run_captured  # noqa: E402

SCENE = "config/queretaro_calibrated.opts"
MAXIMA = ("max_fault_slip_m", "max_fault_opening_m", "max_subsidence_m")


def run(size_factor, solver, ranks, out, extra, scene=SCENE, name=None):
    """One run of ``scene`` (size_factor None: the scene's own mesh, sized by ``extra`` if at all) into
    OUT/NAME (default sf<size factor>_<solver>); returns its row (or the failure)."""
    path = os.path.join(out, name or f"sf{size_factor:g}_{solver}")
    size = [] if size_factor is None else ["-pfault_mesh_size_factor", f"{size_factor:g}"]
    stale = os.path.join(path, "summary.json")
    if os.path.exists(stale):            # a run that fails early must not be read as the previous one
        os.remove(stale)
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = run_captured(["-m", "pfault", scene, *size, "-pfault_solver", solver, "-pfault_output_dir", path,
                         "-pfault_figures", "false", *extra], ranks, cwd=ROOT)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    # CPU time of the ranks (user + system, every rank): on a shared machine less sensitive to the load
    # than the wall time, though a rank that waits for another in MPI also counts its polling
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    row = {"size_factor": size_factor, "solver": solver, "ranks": ranks, "end_to_end_s": wall, "cpu_s": cpu,
           "exit_code": proc.returncode}
    try:
        s = read_summary(path)
    except ValueError:
        s = None
    if s is None:
        row["error"] = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return row
    steps = [r for r in s["steps"] if not r.get("initial")]
    newton = sum(r.get("newton_its", 0) for r in steps)
    krylov = sum(r.get("ksp_its", 0) for r in steps)
    w = s.get("wall_s", {})
    row.update({"converged": s["converged"], "cells": s["mesh"]["cells"], "dofs": s["dofs"],
                "newton_its": newton, "ksp_its": krylov, "ksp_per_newton": krylov / max(newton, 1),
                "max_ksp_per_newton": max([r.get("ksp_per_newton", 0.0) for r in steps], default=0.0),
                "setup_s": w.get("mesh", 0.0) + w.get("setup", 0.0), "solve_s": w.get("solve", 0.0),
                "total_s": w.get("total", 0.0), "memory_peak_mib": s.get("memory_peak_mib")})
    row.update({k: s.get(k, 0.0) for k in MAXIMA})
    return row


def table(rows):
    head = ("| size factor | solver | tets | unknowns | Newton | Krylov/Newton (max step) | set-up s | solve s | "
            "total s | peak MiB per rank | slip m | opening m | subsidence m | max rel. diff. |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    ref = {}
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['size_factor']:g} | {r['solver']} | | | | | | | | | | | | failed: {r['error']} |")
            continue
        base = ref.setdefault(r["size_factor"], r)
        diff = max(abs(r[k] - base[k]) / max(abs(base[k]), 1e-300) for k in MAXIMA)
        mem = "/".join(f"{m:.0f}" for m in r["memory_peak_mib"]) if r.get("memory_peak_mib") else "n/a"
        lines.append(f"| {r['size_factor']:g} | {r['solver']} | {r['cells']:,} | {r['dofs']:,} | {r['newton_its']} | "
                     f"{r['ksp_per_newton']:.1f} ({r['max_ksp_per_newton']:.1f}) | {r['setup_s']:.1f} | "
                     f"{r['solve_s']:.1f} | {r['total_s']:.1f} | {mem} | {r['max_fault_slip_m']:.5g} | "
                     f"{r['max_fault_opening_m']:.5g} | {r['max_subsidence_m']:.5g} | {diff:.2e} |")
    return "\n".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size-factors", default="2,1,0.5")
    p.add_argument("--solvers", default="mumps,iterative")
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--out", default=os.path.join(ROOT, "runs", "solver_scaling"))
    p.add_argument("--force", action="store_true", help="run MUMPS below size factor 1 too")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    rows = []
    for sf in (float(x) for x in a.size_factors.split(",")):
        for solver in a.solvers.split(","):
            if solver == "mumps" and sf < 1 and not a.force:
                print(f"size factor {sf:g}: mumps skipped (beyond the direct solver's memory here)", flush=True)
                continue
            r = run(sf, solver, a.ranks, a.out, extra)
            rows.append(r)
            print(json.dumps(r), flush=True)
    with open(os.path.join(a.out, "results.json"), "w") as fh:
        json.dump(rows, fh, indent=1)
    text = table(rows)
    with open(os.path.join(a.out, "report.md"), "w") as fh:
        fh.write(f"# Solver scaling: {SCENE}, {a.ranks} ranks\n\n{text}\n")
    print(text)
    return 0 if all(r.get("converged") for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
