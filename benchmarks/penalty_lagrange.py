#!/usr/bin/env python
"""Penalty faces against Lagrange faces on the fissure box (config/hard/fissure_box.opts) at h and h/2: the relative
difference of the final opening/slip fields, ||g_pen - g_lag|| / ||g_lag||, for k = 1, 100, 1e4, 1e6 E/h (E/h of
the box's softer top material on its fault faces, as studies/hard_cases.py). Both act on the face-mean jump with
its face bubbles' part (pfault.faults.bubbles), so the difference is the penalty's own, ~1/k, with no share of a
stabilisation left. One step of one year (the drawdown is proportional: later steps scale).

    python benchmarks/penalty_lagrange.py [--ranks 2] [--out runs/penalty_lagrange]

Prints a table and one JSON line.
"""
import argparse
import json
import math
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
from pfault.post import rundir  # noqa: E402
from pfault.post.rundir import read_summary  # noqa: E402
from pfault.tools.runs import run_captured, shown  # noqa: E402

FISSURE = "config/hard/fissure_box.opts"
MESHES = {"h": ("16,8,10", 8.0e6 / math.sqrt(62.5)), "h/2": ("32,16,20", 8.0e6 / math.sqrt(15.625))}
FACTORS = (1.0, 1e2, 1e4, 1e6)
ONE_STEP = ["-pfault_time_steps", "1", "-pfault_time_end", "1*year", "-pfault_material_sand_head_drawdown",
            "0:0,1*year:2", "-pfault_figures", "false"]


def run(out, ranks, extra):
    proc = run_captured(["-m", "pfault", FISSURE, "-pfault_output_dir", out, *ONE_STEP, *extra], ranks, cwd=REPO,
                        timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(f"{shown(proc.args)}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    f = rundir.read_fault(out).cell_data
    s = read_summary(out)
    return np.column_stack([f["opening"], f["slip"]]), max(st["newton_its"] for st in s["steps"] if st["time_s"] > 0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--out", default=os.path.join("runs", "penalty_lagrange"))
    a = ap.parse_args()
    res = {}
    for mesh, (cells, e_over_h) in MESHES.items():
        tag = mesh.replace("/", "")
        ref, its = run(os.path.join(a.out, f"lagrange_{tag}"), a.ranks, ["-pfault_box_cells", cells])
        rows = {"lagrange_newton": its}
        for m in FACTORS:
            k = f"{m * e_over_h:.6g}"
            g, its = run(os.path.join(a.out, f"penalty_{m:g}_{tag}"), a.ranks,
                         ["-pfault_box_cells", cells, "-pfault_fault_fissure_method", "penalty",
                          "-pfault_fault_fissure_penalty_normal", k, "-pfault_fault_fissure_penalty_tangential", k])
            rows[f"{m:g}"] = {"difference": float(np.linalg.norm(g - ref) / np.linalg.norm(ref)), "newton": its}
            print(f"{mesh:4s} k = {m:8g} E/h: difference to Lagrange {rows[f'{m:g}']['difference']:.3e}, "
                  f"Newton (largest in a step) {its}", flush=True)
        res[mesh] = rows
    print(json.dumps(res))


if __name__ == "__main__":
    main()
