#!/usr/bin/env python
"""Twin experiment of python -m pfault.calibrate --insar on the example site (studies/insar_twin.py): a synthetic
OPERA DISP-S1-like product (5 mm noise, a random offset per date, 5 % of the values missing), the clay's and the
sand's moduli fitted from a start a factor 2 away.

    .venv/bin/python benchmarks/insar_twin.py [--workers 2] [--out runs/bench_insar_twin]

Prints the fitted values against the truth (in standard errors), the residual variance, the offsets recovered, and
the share of the fit's wall time spent in forward runs (each batch of runs side by side counted by its longest run),
then a JSON line. The calibration's output stays in OUT/fit (insar_fit.png, insar_fit.nc, calibration.json, ...).
"""
import argparse
import csv
import json
import os
import shutil
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies import insar_twin as twin  # noqa: E402


def run_time(runs):
    """Wall time of the forward runs as the fit waits for them: a Jacobian's runs go side by side."""
    total, batch = 0.0, []
    for r in runs:
        if r["purpose"] == "jacobian":
            batch.append(float(r["wall_s"]))
            continue
        total += max(batch, default=0.0) + float(r["wall_s"])
        batch = []
    return total + max(batch, default=0.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="runs/bench_insar_twin")
    args = ap.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    proc, offsets = twin.calibrate(args.out, workers=args.workers)
    if proc.returncode != 0:
        sys.exit(f"calibration failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    s = json.load(open(os.path.join(args.out, "fit", "calibration.json")))
    with open(os.path.join(args.out, "fit", "runs.csv"), newline="") as fh:
        runs = list(csv.DictReader(fh))
    forward = run_time(runs)
    print(f"{s['runs']} runs, phi {s['phi_start']:.4g} -> {s['phi']:.4g}, {s['degrees_of_freedom']} dof, residual "
          f"variance {s['residual_variance']:.4f}; fit {s['wall_s']:.1f} s of which forward runs {forward:.1f} s "
          f"({100 * forward / s['wall_s']:.1f} %)")
    for name, true in twin.TRUE.items():
        f = s["fitted"][name]
        off = np.log10(f["value"] / true) / f["standard_error_log10"]
        print(f"  {name:<7} true {true:.4g}  start {twin.START_VALUES[name]:.4g}  fitted {f['value']:.5g} +/- "
              f"{f['standard_error']:.3g} (log10 se {f['standard_error_log10']:.4f}): {off:+.2f} se")
    err = np.abs(np.array(s["insar"]["offsets_m"]) + offsets).max()
    print(f"  offsets: largest error {1e3 * err:.3f} mm of offsets up to {1e3 * np.abs(offsets).max():.1f} mm; "
          f"{s['insar']['values_used']} values used, {s['insar']['values_skipped_no_data']} without a value")
    print(json.dumps({"fitted": {k: v["value"] for k, v in s["fitted"].items()}, "wall_s": s["wall_s"],
                      "forward_s": forward, "runs": s["runs"], "variance": s["residual_variance"]}))


if __name__ == "__main__":
    main()
