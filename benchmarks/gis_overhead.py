#!/usr/bin/env python
"""What the GIS layers cost (pfault.post.gis, -pfault_crs): the Wuxi case at paper size on 2 ranks (config/wuxi.opts),
run side by side without and with -pfault_crs (and -pfault_start_date, stations and a LOS raster in both), in
alternation, figures off in both.

    .venv/bin/python benchmarks/gis_overhead.py [--repeats 3] [--ranks 2] [--out runs/bench_gis]

Prints per run the wall time of the process and the GIS writing time the run reports, then the medians and the
overhead in percent of the plain run, and a JSON line.
"""
import argparse
import json
import os
import re
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from pfault.tools.runs import environment  # noqa: E402
from studies import REPO  # noqa: E402
from pfault.tools.runs import Run, run_pfault  # noqa: E402

STATIONS = "name,x,y,z\nCREST,501000,3502500,0\nWEST,500500,3502500,0\nEAST,501500,3502500,0\n"
COMMON = {"pfault_insar_los": "-0.618,-0.110,0.778", "pfault_insar_spacing": "50", "pfault_mesh_origin": "500000,3500000,0"}
GIS = {"pfault_crs": "EPSG:32650", "pfault_start_date": "2015-01-01"}


def one(out, overrides, ranks, gis):
    t0 = time.perf_counter()
    r = run_pfault(Run("config/wuxi.opts", out, overrides, ranks=ranks, gis=gis, timeout=1800), cwd=REPO,
                   env=environment())
    wall = time.perf_counter() - t0
    if not r.ok:
        sys.exit(f"run failed: {r.error}")
    text = open(r.log).read()
    m = re.search(r"(\d+) GIS files in gis/ in ([0-9.]+) s", text)
    return wall, (float(m.group(2)) if m else 0.0), (int(m.group(1)) if m else 0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--out", default="runs/bench_gis")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    stations = os.path.abspath(os.path.join(args.out, "stations.csv"))
    open(stations, "w").write(STATIONS)
    base = {**COMMON, "pfault_stations": stations}
    plain, gis, writes = [], [], []
    for k in range(args.repeats):
        w, _, _ = one(os.path.join(args.out, f"plain_{k}"), base, args.ranks, False)
        plain.append(w)
        w2, g, n = one(os.path.join(args.out, f"gis_{k}"), {**base, **GIS}, args.ranks, True)
        gis.append(w2)
        writes.append(g)
        print(f"repeat {k}: plain {w:.1f} s, with -pfault_crs {w2:.1f} s (GIS files: {n} in {g:.2f} s), load "
              f"{os.getloadavg()[0]:.1f}", flush=True)
    mp, mg, mw = statistics.median(plain), statistics.median(gis), statistics.median(writes)
    print(f"median: plain {mp:.1f} s, with -pfault_crs {mg:.1f} s ({100 * (mg - mp) / mp:+.1f} %); GIS writing "
          f"{mw:.2f} s = {100 * mw / mp:.1f} % of the plain run")
    print(json.dumps({"plain_s": plain, "gis_s": gis, "gis_write_s": writes, "ranks": args.ranks}))


if __name__ == "__main__":
    main()
