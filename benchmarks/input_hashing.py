#!/usr/bin/env python
"""What recording a run's data files costs: the SHA-256 of each (pfault.provenance.describe, as a run does on
rank 0 at start-up), for the example site's files and for the 1-million-cell MODFLOW head file of
benchmarks/heads_read.py (88 MB at 11 saved times; written into runs/bench_heads/ if it is not there).

    .venv/bin/python benchmarks/input_hashing.py [--repeat 5]

Prints each file's size, the median and fastest of ``--repeat`` hashes, the rate, and a JSON line. The first
hash of a file may read it from disk; the others from the page cache, as a run that has just read it does.
"""
import argparse
import glob
import json
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from pfault.provenance import describe  # noqa: E402

SITE = os.path.join(os.path.dirname(HERE), "config", "site_example")
BIG = os.path.join("runs", "bench_heads")


def timed(path, repeat):
    """(size in bytes, [seconds of each hash])."""
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        entry = describe("file", path)
        out.append(time.perf_counter() - t0)
    return entry["size_bytes"], out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    os.makedirs(BIG, exist_ok=True)
    big = os.path.join(BIG, "big11.hds")
    if not os.path.exists(big):
        sys.path.insert(0, HERE)
        from heads_read import write_model
        write_model(BIG, 11)
    files = sorted(glob.glob(os.path.join(SITE, "*.hds")) + glob.glob(os.path.join(SITE, "*.grb"))
                   + glob.glob(os.path.join(SITE, "*.csv"))) + [big]
    rows = []
    for path in files:
        size, times = timed(path, args.repeat)
        med, best = statistics.median(times), min(times)
        rows.append({"file": os.path.relpath(path), "bytes": size, "median_s": med, "fastest_s": best,
                     "mb_per_s": size / best / 1e6})
        print(f"{os.path.relpath(path):45s} {size:>12,} bytes  median {med * 1e3:9.3f} ms  fastest "
              f"{best * 1e3:9.3f} ms  {size / best / 1e6:8.0f} MB/s", flush=True)
    site = sum(r["median_s"] for r in rows if r["file"].startswith(os.path.relpath(SITE)))
    print(f"the example site's data files together: {site * 1e3:.3f} ms")
    print(json.dumps({"files": rows, "site_total_s": site}))


if __name__ == "__main__":
    main()
