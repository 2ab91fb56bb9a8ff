"""Queretaro's water-management plans (config/queretaro_plans.opts) compared at several mesh sizes.

    .venv/bin/python -m studies.scenarios                    # size factors 4 and 2, 2 plans at a time (~3 min)
    .venv/bin/python -m studies.scenarios --factors 6,4,3,2 --workers 1

For every mesh size factor, ``python -m pfault.scenarios config/queretaro.opts config/queretaro_plans.opts
--output runs/queretaro_plans-f<factor> -pfault_mesh_size_factor <factor>`` runs the baseline and the three plans
(pumping stopped after year 5, halved, the middle well moved east) and prints its table. Then one table of every
plan's figures relative to the baseline at each size: what a comparison of plans rests on is that these ratios,
and the order of the plans, hold as the mesh is refined, even where the figures themselves have not converged
(docs/scenarios.md: the figures at sizes 6 to 2).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

from pfault.tools.runs import run_logged

from . import REPO

SCENE, PLANS = "config/queretaro.opts", "config/queretaro_plans.opts"
COMPARED = ("max_subsidence_m", "final_subsidence_m", "max_fault_opening_m", "max_fault_slip_m",
            "max_horizontal_strain", "max_fissure_prone_length_m")


def run_factor(factor: str, workers: int) -> tuple[dict, float, int]:
    out = os.path.join("runs", f"queretaro_plans-f{factor}")
    args = ["-m", "pfault.scenarios", SCENE, PLANS, "--output", out, "--workers", str(workers),
            "-pfault_mesh_size_factor", factor]
    done = run_logged(args, 1, os.path.join(REPO, out + ".log"), cwd=REPO)
    print(f"$ {done.command}  (log {out}.log)", flush=True)
    code, wall = done.code, done.wall
    with open(os.path.join(REPO, out, "scenarios.csv"), newline="") as fh:
        rows = {r["plan"]: r for r in csv.DictReader(fh)}
    return rows, wall, code


def ratio(row: dict, base: dict, key: str) -> str:
    if not row[key] or not base[key]:
        return "-"
    b = float(base[key])
    return f"{float(row[key]) / b:.3f}" if b else ("0" if float(row[key]) == 0 else "inf")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factors", default="4,2", help="mesh size factors, comma-separated")
    ap.add_argument("--workers", type=int, default=2, help="plans run side by side")
    a = ap.parse_args(argv)
    results = {}
    for factor in a.factors.split(","):
        rows, wall, code = run_factor(factor, a.workers)
        results[factor] = rows
        print(f"factor {factor}: exit {code}, {wall:.1f} s for {len(rows)} plans\n", flush=True)
    print("every plan relative to the baseline (value / baseline value):")
    head = ["plan", "factor", *COMPARED]
    lines = [head]
    for factor, rows in results.items():
        base = rows["baseline"]
        for plan, row in rows.items():
            if plan != "baseline":
                lines.append([plan, factor, *[ratio(row, base, k) for k in COMPARED]])
    width = [max(len(x[k]) for x in lines) for k in range(len(head))]
    for x in lines:
        print("  ".join(v.ljust(width[k]) if k < 2 else v.rjust(width[k]) for k, v in enumerate(x)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
