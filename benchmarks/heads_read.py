#!/usr/bin/env python
"""Time to read a 1-million-cell MODFLOW 6 head file and look up the cells of a paper-size mesh in it.

    mpirun -n 2 .venv/bin/python benchmarks/heads_read.py [--cells 302106] [--times 11] [--repeat 3]

Writes (once) runs/bench_heads/big.dis.grb and big.hds: a DIS model of 10 layers x 250 rows x 400 columns of
50 m (1,000,000 cells), rotated 15 degrees, heads saved at ``--times`` times. Then every rank builds the
pore-pressure source of pfault.sources.heads for its share of ``--cells`` cell centroids (default: the
tetrahedra of paper-size Queretaro, 302,106; Wuxi has 122,145), uniformly spread over the model, as a run does:
grid file, head file scan, the cell map, every saved time gathered for its cells. Each build is timed between two
barriers; prints the median and fastest, each phase's share on rank 0, the memory the table holds and a JSON line.
"""
import argparse
import json
import os
import time

import numpy as np
from mpi4py import MPI

from pfault.sources import head_files
from pfault.sources.heads import HeadsSettings, build_heads_source
from pfault.tools.mf6_write import write_dis_grb, write_heads

NLAY, NROW, NCOL, CELL = 10, 250, 400, 50.0
ANGROT, ORIGIN = 15.0, (3.0e5, 4.0e6)


def write_model(d, ntimes):
    grb, hds = os.path.join(d, "big.dis.grb"), os.path.join(d, f"big{ntimes}.hds")
    if not os.path.exists(grb):
        top = np.zeros((NROW, NCOL))
        botm = -np.arange(1, NLAY + 1)[:, None, None] * 20.0 * np.ones((NLAY, NROW, NCOL))
        write_dis_grb(grb, np.full(NCOL, CELL), np.full(NROW, CELL), top, botm, xorigin=ORIGIN[0],
                      yorigin=ORIGIN[1], angrot=ANGROT)
    if not os.path.exists(hds):
        rng = np.random.default_rng(0)
        base = rng.normal(size=(NLAY, NROW, NCOL))
        write_heads(hds, np.arange(ntimes) * 365.25, np.stack([base - 0.5 * i for i in range(ntimes)]))
    return grb, hds


def centroids(n, seed):
    """n points uniformly inside the model (its local frame rotated into site coordinates)."""
    rng = np.random.default_rng(seed)
    local = np.stack([rng.uniform(0, NCOL * CELL, n), rng.uniform(0, NROW * CELL, n)], axis=1)
    a = np.deg2rad(ANGROT)
    xy = np.stack([local[:, 0] * np.cos(a) - local[:, 1] * np.sin(a) + ORIGIN[0],
                   local[:, 0] * np.sin(a) + local[:, 1] * np.cos(a) + ORIGIN[1]], axis=1)
    return np.column_stack([xy, rng.uniform(-NLAY * 20.0, 0.0, n)])


def phases(settings, points):
    """Seconds of each phase of one build on this rank (the same work as build_heads_source)."""
    t = [time.perf_counter()]
    grid = head_files.read_mf6_grid(settings.grid)
    t.append(time.perf_counter())
    heads = head_files.Mf6Heads(settings.file, grid, settings.grid)
    t.append(time.perf_counter())
    cell = grid.cells(points)
    t.append(time.perf_counter())
    for i in range(len(heads.times)):
        heads.values(i)[cell]
    t.append(time.perf_counter())
    heads.close()
    return dict(zip(("grid_file", "head_scan", "cell_map", "read_and_gather"), np.diff(t)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cells", type=int, default=302106)
    ap.add_argument("--times", type=int, default=11)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    comm = MPI.COMM_WORLD
    d = os.path.join("runs", "bench_heads")
    if comm.rank == 0:
        os.makedirs(d, exist_ok=True)
        grb, hds = write_model(d, a.times)
    grb, hds = comm.bcast((grb, hds) if comm.rank == 0 else None)
    n_local = a.cells // comm.size + (comm.rank < a.cells % comm.size)
    points = centroids(n_local, comm.rank)
    s = HeadsSettings(file=hds, grid=grb, time_unit=86400.0, time_unit_given=True, length_unit=1.0,
                      reference_time=None, outside="zero", origin=(0.0, 0.0, 0.0), water_density=1000.0,
                      gravity=9.80665)
    walls = []
    for _ in range(a.repeat):
        comm.Barrier()
        t0 = time.perf_counter()
        src = build_heads_source(comm, s, points)
        comm.Barrier()
        walls.append(time.perf_counter() - t0)
    split = phases(s, points)
    if comm.rank == 0:
        size = os.path.getsize(hds) / 1e6
        result = {"ranks": comm.size, "model_cells": NLAY * NROW * NCOL, "saved_times": a.times,
                  "head_file_MB": round(size, 1), "mesh_cells": a.cells, "median_s": float(np.median(walls)),
                  "fastest_s": float(np.min(walls)), "rank0_phases_s": {k: round(float(v), 3) for k, v in split.items()},
                  "table_MB_per_rank": round(src.table.nbytes / 1e6, 1),
                  "load_1min": os.getloadavg()[0]}
        print(f"{NLAY * NROW * NCOL:,}-cell DIS model, {a.times} saved times ({size:.0f} MB), {a.cells:,} mesh cells on "
              f"{comm.size} rank(s): build median {result['median_s']:.2f} s, fastest {result['fastest_s']:.2f} s")
        print("rank 0 phases: " + ", ".join(f"{k} {v:.3f} s" for k, v in split.items()))
        print(json.dumps(result))


if __name__ == "__main__":
    main()
