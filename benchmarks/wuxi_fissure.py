#!/usr/bin/env python
"""Wuxi with a fissure that forms (config/wuxi_fissure.opts) against the plain Wuxi scene (config/wuxi.opts), at
paper size, one run after the other on the same ranks: wall times, Newton iterations, and the fissure: when it
first broke, when it reached the land surface, how deep it cut, its length along the surface and its opening.

    python benchmarks/wuxi_fissure.py [--ranks 2] [--size-factor 1] [--out runs/wuxi_fissure] [-- -option value ...]

Options after ``--`` go to both runs. Targets (issue 32): the fissure scene's wall time at most 1.5 times the plain
one's (end to end, the same figures written), at most 15 Newton iterations in any step, converged with no contact
option. Prints a table per output time of the fissure run, the comparison, and one JSON line; the exit code is 0
when both runs completed (targets met or not), 1 when a run failed. The run directories (with fissure_break.png and
hazard_map.png) stay under --out.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
from pfault.post import fissures, meshes, rundir  # noqa: E402
from pfault.post.rundir import read_summary  # noqa: E402
from pfault.units import YEAR  # noqa: E402
from pfault.tools.runs import run_logged  # noqa: E402

SCENES = {"plain": "config/wuxi.opts", "fissure": "config/wuxi_fissure.opts"}
MAX_WALL_RATIO = 1.5
MAX_NEWTON = 15


def run(name: str, args: argparse.Namespace) -> dict | None:
    """One scene, logged; returns its figures (None for a failed run, its log's last lines printed)."""
    out = os.path.join(args.out, name)
    cmd = ["-m", "pfault", SCENES[name], "-pfault_output_dir", out, "-pfault_mesh_size_factor",
           str(args.size_factor), "-pfault_figures", "true", *args.extra]
    log = run_logged(cmd, args.ranks, os.path.join(args.out, f"{name}.log"), args.timeout, cwd=REPO)
    summary = read_summary(out)
    print(f"{name}: {log.command}\n  exit {log.code}{' (timed out)' if log.timed_out else ''}, "
          f"{log.wall:.1f} s end to end, load {log.load:.2f}", flush=True)
    if log.code != 0 or summary is None:
        lines = log.output.strip().splitlines()
        print("  " + "\n  ".join([ln for ln in lines if ln.startswith("pfault:")][-3:] or lines[-5:]))
        return None
    steps = [r for r in summary["steps"] if r.get("time_s", 0.0) > 0.0]
    return {"dir": out, "wall_s": log.wall, "load": log.load, "solve_s": summary["wall_s"]["solve"],
            "newton_max": max(r["newton_its"] for r in steps), "newton_total": sum(r["newton_its"] for r in steps),
            "converged": bool(summary["converged"]), "max_opening_m": summary.get("max_fault_opening_m", 0.0),
            "surface_opening_m": meshes.surface_fault_jumps(rundir.read_fields(out), rundir.read_fault(out))[0],
            "summary": summary}


def history(run_dir: str) -> list[dict]:
    """The fissure at every output time of a run (pfault.post.fissures.history): broken faces, depth, surface
    length, largest opening of a broken face."""
    last = fissures.read_breaks(run_dir)
    if last is None:
        return []
    h = fissures.history(run_dir).get("fissure")
    rows = []
    for k in range(last.num_steps):
        b = fissures.read_breaks(run_dir, k)
        rows.append({"year": b.time / YEAR, "broken": int(b.broken.sum()), "faces": len(b.broken),
                     **{key: float(h[key][k]) if h else 0.0 for key in ("broken_depth_m", "broken_length_m",
                                                                         "max_opening_m")}})
    return rows


def report(plain: dict, fis: dict) -> dict:
    """Print the fissure's history and the comparison; returns the figures of the JSON line."""
    rows = history(fis["dir"])
    print("\n| year | broken faces | depth (m) | surface length (m) | largest opening (cm) |\n|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['year']:.3g} | {r['broken']} of {r['faces']} | {r['broken_depth_m']:.3g} | "
              f"{r['broken_length_m']:.5g} | {100 * r['max_opening_m']:.3g} |")
    last = fissures.read_breaks(fis["dir"])
    m = fissures.measures(fis["dir"], last).get("fissure", {}) if last is not None and last.broken.any() else {}
    ratio = fis["wall_s"] / plain["wall_s"]
    out = {"wall_plain_s": plain["wall_s"], "wall_fissure_s": fis["wall_s"], "wall_ratio": ratio,
           "solve_plain_s": plain["solve_s"], "solve_fissure_s": fis["solve_s"],
           "load": [plain["load"], fis["load"]], "newton_max": [plain["newton_max"], fis["newton_max"]],
           "newton_total": [plain["newton_total"], fis["newton_total"]], "converged": fis["converged"],
           "first_break_year": m.get("first_break_time_s", np.nan) / YEAR,
           "surface_year": m.get("surface_break_time_s", np.nan) / YEAR, "depth_m": m.get("broken_depth_m", 0.0),
           "length_m": m.get("broken_length_m", 0.0), "area_m2": m.get("broken_area_m2", 0.0),
           "max_opening_m": [plain["max_opening_m"], fis["max_opening_m"]],
           "surface_opening_m": [plain["surface_opening_m"], fis["surface_opening_m"]]}
    met = {"wall": ratio <= MAX_WALL_RATIO, "newton": fis["newton_max"] <= MAX_NEWTON, "converged": fis["converged"]}
    print(f"\nwall time end to end: plain {plain['wall_s']:.1f} s, fissure {fis['wall_s']:.1f} s, ratio {ratio:.2f} "
          f"(target <= {MAX_WALL_RATIO}: {'met' if met['wall'] else 'NOT met'}); solve stage {plain['solve_s']:.1f} s "
          f"/ {fis['solve_s']:.1f} s; mean load {plain['load']:.2f} / {fis['load']:.2f}")
    print(f"Newton iterations, largest in a step: plain {plain['newton_max']}, fissure {fis['newton_max']} "
          f"(target <= {MAX_NEWTON}: {'met' if met['newton'] else 'NOT met'}); total {plain['newton_total']} / "
          f"{fis['newton_total']}; converged: {fis['converged']}")
    print(f"fissure: first break at {out['first_break_year']:.3g} years, at the land surface at "
          f"{out['surface_year']:.3g} years; {out['depth_m']:.3g} m deep, {out['length_m']:.5g} m along the surface, "
          f"{out['area_m2']:.5g} m^2; largest opening {100 * fis['max_opening_m']:.3g} cm (face average; plain "
          f"{100 * plain['max_opening_m']:.3g} cm), {100 * fis['surface_opening_m']:.3g} cm at the land surface "
          f"(plain {100 * plain['surface_opening_m']:.3g} cm)")
    out["targets_met"] = met
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--size-factor", type=float, default=1.0)
    ap.add_argument("--out", default=os.path.join(REPO, "runs", "wuxi_fissure"))
    ap.add_argument("--timeout", type=float, default=3600.0)
    args = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    args.extra = extra
    args.out = os.path.abspath(args.out)
    plain = run("plain", args)           # one after the other: never two MPI jobs at once
    fis = run("fissure", args)
    if plain is None or fis is None:
        return 1
    print(json.dumps(report(plain, fis)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
