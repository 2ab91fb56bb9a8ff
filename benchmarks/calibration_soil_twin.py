#!/usr/bin/env python
"""Twin experiment of python -m pfault.calibrate on soils that remember, at the scene's own size:
config/seasonal.opts (6 x 6 x 40 hexahedra as 8,640 tetrahedra, 96 monthly steps over 8 years: seasonal head cycles
on a declining trend over a clay preconsolidated 2 m below the initial heads and a normally consolidated sand), the
settlement of its two benchmarks every two months (2 x 48 values) with 2 mm Gaussian noise (fixed seed); the clay's
compression index Cc, recompression index Cr and preconsolidation head fitted from Cc 0.15, Cr 0.08 and -3.5 m
(truth 0.30, 0.04, -2 m). Then the same with the clay preconsolidated 8 m below (deeper than its lowest head of the
record, -7.125 m): Cc and Cr fitted, Cc reported not identifiable.

    .venv/bin/python benchmarks/calibration_soil_twin.py [--cases trend,deep] [--workers 2] [--out runs/bench_soil_twin]

Prints per case the fitted values with their standard errors against the truth (how many standard errors away),
the correlations, the runs and the wall time, and a JSON line. Each calibration's output stays in OUT/<case>/fit
(observed_vs_simulated.png, parameters.csv, runs.csv, ...).
"""
import argparse
import json
import os
import shutil
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.calibration_twin import report  # noqa: E402
from studies import calibration_twin as twin  # noqa: E402

SCENE = "config/seasonal.opts"
DAYS = twin.step_days(8, 48)            # every two months: the scene's head table's points
CASES = {"trend": lambda: twin.soil_twin(SCENE),
         "deep": lambda: twin.soil_twin(SCENE, preconsolidation_head=-8.0, names=("Cc_clay", "Cr_clay"))}


def one(out, case, workers):
    shutil.rmtree(out, ignore_errors=True)
    t = CASES[case]()
    t0 = time.perf_counter()
    proc = twin.calibrate(out, DAYS, workers=workers, twin=t, timeout=6 * 3600)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"calibration failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return report(out, t, wall, case)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="trend,deep")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="runs/bench_soil_twin")
    args = ap.parse_args()
    results = [one(os.path.join(args.out, case), case, args.workers) for case in args.cases.split(",")]
    print(json.dumps(results))


if __name__ == "__main__":
    main()
