#!/usr/bin/env python
"""Penny-shaped crack under remote tension (Sneddon): accuracy of the fault opening under refinement.

    .venv/bin/python benchmarks/penny_crack.py [--levels 4 6 8 10 12 16] [--ranks 1] [--L 8]
                                               [--out runs/penny_crack]

For each level n (element size a/n at the crack, a/(3n) at its tip; tests/scripts/penny_mesh.py)
makes the quarter-model mesh, runs config/penny_crack.opts on it (``python -m pfault``, under mpirun
for --ranks > 1) and prints one table row: tetrahedra, dofs, crack faces, the error of the largest
face opening against w0, the error of the face nearest to the centre, the area-weighted RMS error
over the crack divided by w0, the observed rates (h = a/n) against the previous level, the states
(stick/slip/open) and the wall times (meshing; pfault run as measured here, and as pfault reports it).
A JSON line with every figure ends the output.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
sys.path.insert(0, os.path.join(REPO, "tests", "scripts"))
from penny_mesh import crack_errors, make_penny_mesh  # noqa: E402
from pfault.post.rundir import read_summary  # noqa: E402
from pfault.tools.runs import run_captured  # noqa: E402

SCENE = os.path.join(REPO, "config", "penny_crack.opts")


def run_pfault(mesh, out, ranks, extra=()):
    t0 = time.perf_counter()
    proc = run_captured(["-m", "pfault", SCENE, "-pfault_mesh_file", mesh, "-pfault_output_dir", out, *extra], ranks,
                        cwd=REPO)
    return proc, read_summary(out), time.perf_counter() - t0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--levels", type=int, nargs="+", default=[4, 6, 8, 10, 12, 16])
    p.add_argument("--ranks", type=int, default=1)
    p.add_argument("--a", type=float, default=1.0)
    p.add_argument("--L", type=float, default=8.0)
    p.add_argument("--out", default=os.path.join(REPO, "runs", "penny_crack"))
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    rows = []
    print(f"penny crack a = {args.a:g} m, L = {args.L:g} m, {args.ranks} rank(s): errors of the face openings "
          "against Sneddon's w(r)")
    print(f"{'n':>3} {'tets':>8} {'dofs':>8} {'faces':>6} {'max err':>8} {'centre':>8} {'RMS err':>8} "
          f"{'rate max':>8} {'rate RMS':>8} {'stick/slip/open':>16} {'mesh s':>7} {'run s':>7} {'pfault s':>8}")
    for n in args.levels:
        mesh = os.path.join(args.out, f"penny{n}.msh")
        t0 = time.perf_counter()
        m = make_penny_mesh(mesh, args.a, args.L, n)
        mesh_s = time.perf_counter() - t0
        out = os.path.join(args.out, f"n{n}_r{args.ranks}")
        proc, summary, wall = run_pfault(mesh, out, args.ranks)
        if proc.returncode != 0:
            print(f"n = {n}: pfault exited {proc.returncode}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
            break
        e = crack_errors(out, a=args.a)
        row = {"n": n, "tets": m["tets"], "nodes": m["nodes"], "dofs": summary["dofs"], "faces": e["faces"],
               "max_error": e["max_error"], "centre_error": e["centre_error"], "rms_error": e["rms_error"],
               "states": e["states"], "mesh_s": round(mesh_s, 2), "run_s": round(wall, 2),
               "pfault_s": round(summary["wall_s"]["total"], 2), "ranks": args.ranks}
        rate = ["", ""]
        if rows:
            prev = rows[-1]
            h = np.log(n / prev["n"])
            row["rate_max"] = float(np.log(abs(prev["max_error"]) / abs(e["max_error"])) / h)
            row["rate_rms"] = float(np.log(prev["rms_error"] / e["rms_error"]) / h)
            rate = [f"{row['rate_max']:.2f}", f"{row['rate_rms']:.2f}"]
        rows.append(row)
        print(f"{n:>3} {m['tets']:>8} {summary['dofs']:>8} {e['faces']:>6} {100 * e['max_error']:>+7.2f}% "
              f"{100 * e['centre_error']:>+7.2f}% {100 * e['rms_error']:>7.2f}% {rate[0]:>8} {rate[1]:>8} "
              f"{'/'.join(map(str, e['states'])):>16} {mesh_s:>7.2f} {wall:>7.2f} {summary['wall_s']['total']:>8.2f}",
              flush=True)

    result = {"a": args.a, "L": args.L, "ranks": args.ranks, "levels": rows}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
