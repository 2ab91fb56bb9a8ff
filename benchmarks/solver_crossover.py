#!/usr/bin/env python
"""Where the iterative solver overtakes MUMPS: the size behind pfault.solver.choice.ITERATIVE_FROM_DOFS.

    .venv/bin/python benchmarks/solver_crossover.py [--cases queretaro,wuxi,box] [--repeat 2] [--ranks 2]
                                                    [--out runs/solver_crossover]
                                                    [--results benchmarks/results/solver_crossover]
                                                    [--report-only]

Runs each scene and size of CASES with -pfault_solver mumps and -pfault_solver iterative, interleaved (mumps,
iterative, mumps, iterative, ...: the machine is shared, so a change of load falls on both), all time steps
on 2 ranks, through benchmarks/solver_scaling.run. Each run's wall time is end to end (MPI start-up,
imports, mesh, set-up, solve, output); the table gives the minimum of the repeats and every repeat, the
minimum CPU time of the ranks (less sensitive to the load), the 1-min load average before each run, the
unknowns, Newton and Krylov iterations, and the largest relative difference of the maxima (fault slip,
opening, subsidence) between the two solvers. The rows go to RESULTS/results.json and the table to
RESULTS/report.md (both rewritten after each case); the runs' output to OUT (git-ignored). --report-only
rewrites the table from the results. Each scene's sizes run in turn, smallest first; at the paper's size,
calibrated Queretaro with MUMPS takes 86-111 s on an idle machine, about 4 times that at a load of 10.
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from solver_scaling import MAXIMA, ROOT, run  # noqa: E402

SOLVERS = ("mumps", "iterative")
# scene -> (options file, [(size label, size factor or None, extra options)])
CASES = {
    "queretaro": ("config/queretaro_calibrated.opts",
                  [(f"sf {f:g}", f, []) for f in (3, 2, 1.5, 1)]),
    "wuxi": ("config/wuxi.opts", [(f"sf {f:g}", f, []) for f in (1.5, 1, 0.8)]),
    # the demo scene's layered box (no fault, geostatic start): one linear solve per step
    "box": ("config/demo.opts", [(f"cells {c}", None, ["-pfault_box_cells", c]) for c in ("24,24,12", "36,36,18")]),
}
# The maxima of the two solvers agree to what their tolerances leave, not to round-off: a fault step's Newton
# iterations stop at an absolute tolerance from the step's load (Problem._load_tolerance) and the iterative
# solver's Krylov solves at a tenth of it, where MUMPS solves each Newton system to round-off; an elastic
# scene's iterative solve stops at -ksp_rtol 1e-8. tests/test_iterative.py measured that reach on the coarse
# calibrated Queretaro: up to 4e-5 of the opening's largest value, 1.5e-5 of the shear traction's. Measured
# here: up to 1.9e-5 (Wuxi's slip at size factor 1.5, 17 mm), 2e-6 or less elsewhere. Flagged beyond
AGREE_RTOL = 1e-4


def rel_diff(a, b):
    """Largest relative difference of the maxima of two rows (0 where both are 0)."""
    return max(abs(a[k] - b[k]) / max(abs(a[k]), abs(b[k]), 1e-300) if a[k] or b[k] else 0.0 for k in MAXIMA)


def measure(scene, label, size_factor, extra, repeat, ranks, out):
    """Both solvers ``repeat`` times, interleaved; returns the case's row."""
    runs = {s: [] for s in SOLVERS}
    when = {"date": time.strftime("%Y-%m-%d %H:%M"), "uptime": [_uptime()]}
    for i in range(repeat):
        for solver in SOLVERS:
            load = os.getloadavg()[0]
            name = f"{os.path.basename(scene)[:-5]}_{label.replace(' ', '').replace(',', 'x')}_{solver}_{i}"
            r = run(size_factor, solver, ranks, out, extra, scene=scene, name=name)
            r["load_before"] = load
            runs[solver].append(r)
            print(f"  {label} {solver} #{i + 1}: "
                  + (f"failed: {r['error']}" if "error" in r else
                     f"{r['end_to_end_s']:.1f} s ({r['cpu_s']:.1f} s CPU), {r['dofs']:,} dofs, "
                     f"{r['newton_its']} Newton, {r['ksp_its']} Krylov, load {load:.2f}"), flush=True)
    when["uptime"].append(_uptime())
    row = {"scene": scene, "size": label, "size_factor": size_factor, "extra": extra, "runs": runs, **when}
    if any("error" in r or not r.get("converged") for rs in runs.values() for r in rs):
        row["failed"] = True
        return row
    m, it = runs["mumps"][0], runs["iterative"][0]
    row.update({"dofs": m["dofs"], "cells": m["cells"],
                "newton_its": {s: runs[s][0]["newton_its"] for s in SOLVERS},
                "ksp_its": {s: runs[s][0]["ksp_its"] for s in SOLVERS},
                "wall_s": {s: min(r["end_to_end_s"] for r in runs[s]) for s in SOLVERS},
                "cpu_s": {s: min(r["cpu_s"] for r in runs[s]) for s in SOLVERS},
                "max_rel_diff": max(rel_diff(m, r) for rs in runs.values() for r in rs),
                "maxima": {k: it[k] for k in MAXIMA}})
    row["ratio"] = row["wall_s"]["mumps"] / row["wall_s"]["iterative"]
    row["cpu_ratio"] = row["cpu_s"]["mumps"] / row["cpu_s"]["iterative"]
    return row


def table(rows):
    head = ("| scene | size | dofs | Newton mumps/iter. | Krylov mumps/iter. | mumps s (min; runs) | "
            "iterative s (min; runs) | mumps/iterative | CPU s mumps/iter. (min) | CPU mumps/iterative | "
            "max rel. diff. of the maxima | load before runs |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        scene = os.path.basename(r["scene"])
        if r.get("failed"):
            errs = "; ".join(f"{x['solver']}: {x.get('error', 'not converged')}" for rs in r["runs"].values()
                             for x in rs if "error" in x or not x.get("converged"))
            lines.append(f"| {scene} | {r['size']} | | | | | | | | | failed: {errs} | |")
            continue
        walls = {s: ", ".join(f"{x['end_to_end_s']:.1f}" for x in r["runs"][s]) for s in SOLVERS}
        loads = ", ".join(f"{x['load_before']:.1f}" for i in range(len(r["runs"]["mumps"]))
                          for x in (r["runs"]["mumps"][i], r["runs"]["iterative"][i]))
        flag = "" if r["max_rel_diff"] <= AGREE_RTOL else f" (beyond {AGREE_RTOL:g})"
        lines.append(f"| {scene} | {r['size']} | {r['dofs']:,} | {r['newton_its']['mumps']}/"
                     f"{r['newton_its']['iterative']} | {r['ksp_its']['mumps']}/{r['ksp_its']['iterative']} | "
                     f"{r['wall_s']['mumps']:.1f} ({walls['mumps']}) | {r['wall_s']['iterative']:.1f} "
                     f"({walls['iterative']}) | {r['ratio']:.2f} | "
                     f"{r['cpu_s']['mumps']:.0f}/{r['cpu_s']['iterative']:.0f} | {r['cpu_ratio']:.2f} | "
                     f"{r['max_rel_diff']:.1e}{flag} | {loads} |")
    return "\n".join(lines)


def _git_head():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                              text=True).stdout.strip()
    except OSError:
        return "?"


def _uptime():
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def write(rows, meta, results):
    """RESULTS/results.json and RESULTS/report.md of the rows so far (rewritten after every case)."""
    with open(os.path.join(results, "results.json"), "w") as fh:
        json.dump({"meta": meta, "rows": rows}, fh, indent=1)
    text = table(rows)
    runs = [meta]
    while "merged_into" in runs[-1]:
        runs.append(runs[-1]["merged_into"])
    head = "\n\n".join(f"git {m['git']}, {m['date']}: `uptime` before {m['uptime'][0]}; after {m['uptime'][-1]}"
                         for m in runs)
    with open(os.path.join(results, "report.md"), "w") as fh:
        fh.write(f"# Solver crossover, {meta['ranks']} ranks, {meta['repeat']} runs of each solver interleaved\n\n"
                 f"{head}\n\n(each row's runs: its \"date\" and \"uptime\" in results.json)\n\n{text}\n")
    return text


def _merged(kept, rows):
    """``rows`` in place of the rows of ``kept`` with their scene and size, in the order of CASES."""
    new = {(r["scene"], r["size"]): r for r in rows}
    both = {**{(r["scene"], r["size"]): r for r in kept}, **new}
    order = [(scene, label) for scene, sizes in CASES.values() for label, _, _ in sizes]
    return [both[k] for k in order if k in both] + [r for k, r in both.items() if k not in order]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default=",".join(CASES))
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--out", default=os.path.join(ROOT, "runs", "solver_crossover"))
    p.add_argument("--results", default=os.path.join(HERE, "results", "solver_crossover"))
    p.add_argument("--report-only", action="store_true", help="rewrite RESULTS/report.md from RESULTS/results.json")
    p.add_argument("--merge", action="store_true", help="keep RESULTS/results.json's rows of the scenes and sizes "
                   "not run now (a rerun of some cases)")
    a = p.parse_args(argv)
    if a.report_only:
        with open(os.path.join(a.results, "results.json")) as fh:
            data = json.load(fh)
        print(write(data["rows"], data["meta"], a.results))
        return 0
    os.makedirs(a.out, exist_ok=True)
    os.makedirs(a.results, exist_ok=True)
    meta = {"git": _git_head(), "date": time.strftime("%Y-%m-%d %H:%M"), "ranks": a.ranks, "repeat": a.repeat,
            "agree_rtol": AGREE_RTOL, "uptime": [_uptime()]}
    print(f"uptime: {meta['uptime'][0]}", flush=True)
    t0 = time.perf_counter()
    kept = []
    if a.merge:
        with open(os.path.join(a.results, "results.json")) as fh:
            old = json.load(fh)
        kept = old["rows"]
        meta["merged_into"] = old["meta"]
    rows = []
    for case in a.cases.split(","):
        scene, sizes = CASES[case]
        for label, factor, extra in sizes:
            print(f"{scene} {label}", flush=True)
            rows.append(measure(scene, label, factor, extra, a.repeat, a.ranks, a.out))
            meta["uptime"].append(_uptime())
            meta["benchmark_s"] = time.perf_counter() - t0
            text = write(_merged(kept, rows), meta, a.results)
    print(f"uptime: {meta['uptime'][-1]}", flush=True)
    print(text)
    print(f"benchmark: {meta['benchmark_s']:.0f} s")
    return 0 if all(not r.get("failed") and r["max_rel_diff"] <= AGREE_RTOL for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
