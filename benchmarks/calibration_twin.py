#!/usr/bin/env python
"""Twin experiment of python -m pfault.calibrate, in full: config/twin/twin.opts (clay over sand, one well,
864 tetrahedra, 8 steps to 120 days), 10 measured components at each of 8 times (80), 2 % Gaussian noise
(fixed seed), the two Young's moduli and the pumping rate fitted from a start a factor 2 away.

    .venv/bin/python benchmarks/calibration_twin.py [--workers 1,2] [--out runs/bench_calibration]

Prints, for each number of workers, the fitted values with their standard errors against the truth (how many
standard errors away), the correlations, the runs and the wall time, and a JSON line. The output of each
calibration stays in OUT/workers_N/fit (observed_vs_simulated.png, parameters.csv, runs.csv, ...).
"""
import argparse
import json
import os
import shutil
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies import calibration_twin as twin  # noqa: E402

DAYS = [15, 30, 45, 60, 75, 90, 105, 120]


def report(out, t, wall, label):
    """Prints a calibration's figures against the twin's truth (how many standard errors away; a parameter the
    tool found not identifiable says so) and returns them as a dict."""
    with open(os.path.join(out, "fit", "calibration.json")) as fh:
        s = json.load(fh)
    print(f"\n{label}: {s['runs']} runs, {s['iterations']} Jacobians, wall {wall:.1f} s (fit "
          f"{s['wall_s']:.1f} s, load {os.getloadavg()[0]:.1f}); phi {s['phi_start']:.4g} -> {s['phi']:.4g}, "
          f"{s['degrees_of_freedom']} dof, residual variance {s['residual_variance']:.3f}")
    print(f"  {'parameter':<8} {'true':>10} {'start':>10} {'fitted':>10} {'std err':>9} {'(log10)':>8} {'off/se':>7}")
    for name, true in t.true.items():
        f = s["fitted"][name]
        if not f.get("identifiable", True):
            held = f"NOT IDENTIFIABLE (held at {f['held_at']:.4g})"
            print(f"  {name:<8} {true:10.4g} {t.start[name]:10.4g} {held:>36}")
            continue
        se_x = f.get("standard_error_log10")
        off = np.log10(f["value"] / true) / se_x if se_x else (f["value"] - true) / f["standard_error"]
        print(f"  {name:<8} {true:10.4g} {t.start[name]:10.4g} {f['value']:10.4g} {f['standard_error']:9.3g} "
              f"{se_x or float('nan'):8.4f} {off:7.2f}")
    names = list(t.true)
    corr = s["correlation"]
    print("  correlation: " + ", ".join(f"{names[i]}-{names[j]} " + ("-" if corr[i][j] is None else f"{corr[i][j]:.3f}")
                                          for i in range(len(names)) for j in range(i + 1, len(names))))
    return {"case": label, "wall_s": wall, "runs": s["runs"], "phi": s["phi"],
            "fitted": {k: v["value"] for k, v in s["fitted"].items()},
            "standard_error": {k: v["standard_error"] for k, v in s["fitted"].items()},
            "not_identifiable": s.get("not_identifiable", [])}


def one(out, workers):
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    proc = twin.calibrate(out, DAYS, workers=workers)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"calibration failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return {"workers": workers, **report(out, twin.MODULI, wall, f"workers {workers}")}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--out", default="runs/bench_calibration")
    args = ap.parse_args()
    results = [one(os.path.join(args.out, f"workers_{w}"), int(w)) for w in args.workers.split(",")]
    print(json.dumps(results))


if __name__ == "__main__":
    main()
