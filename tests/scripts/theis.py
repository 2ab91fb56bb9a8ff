#!/usr/bin/env python
"""Verification of the groundwater-flow model (pfault.solver.flow).

Mode ``theis`` (default): a fully penetrating well in a confined aquifer. Quarter domain [0, L]^2 x [-b, 0]
with the well on the corner axis x = y = 0 pumping Q/4 (the planes x = 0 and y = 0 are symmetry planes:
natural no-flow), head fixed (h = 0) on x = L and y = L, top and bottom no-flow. Horizontal node spacing
grows geometrically away from the well; one cell across b. The drawdown -h at T_END at every vertex with
R_MIN <= r <= R_MAX is compared with Theis, s = Q / (4 pi T) E1(r^2 S / (4 T t)), T = K b, S = S_s b (the
far boundary is not felt yet).
    theis.py [n ...]     cells per horizontal direction of each level (default 24 48); 2 n backward-Euler
                         steps of T_END / (2 n)
    prints {"n", "h_min", "max_rel_err", "radii", "rel_err_at", "ksp_its", "head_serial" (first level,
    serial vertex order)}

Mode ``interface``: wells placed on the partition interface (on a vertical mesh edge shared by both ranks
and inside a shared vertical face), settings read from -pfault_ options with read_flow_settings. Checks
that every well load sums to 1 and equals the serial NumPy load; runs two mechanical steps through
``advance_to`` and ``cell_dp``.
    theis.py interface -pfault_... (see tests/verification/test_flow.py)
    prints {"load_sum", "load_diff_vs_serial", "wells", "dp_min", "dp_mean_check", "history", "went_back"}

Options (after the words) go to PETSc (e.g. -flow_ksp_rtol 1e-12).
"""
import json
import sys

import petsc4py

petsc4py.init(sys.argv)  # PETSc skips the leading words (mode, sizes)
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.mesh import distributed  # noqa: E402
from pfault.mesh.box import box_mesh  # noqa: E402
from pfault.physics import flow as fl  # noqa: E402
from pfault.solver.flow import FIXED_HEAD_BIT, GroundwaterFlow  # noqa: E402

L, B = 4000.0, 20.0          # m: quarter-domain side, aquifer thickness
K, SS = 1e-4, 1e-5           # m/s, 1/m
Q = 0.01                     # m**3/s of the full well
T_END = 86400.0              # s
R_MIN, R_MAX = 20.0, 200.0   # m
GRADING = 6.8                # x = L (exp(a xi) - 1) / (exp(a) - 1): first cell ~ 30/n m


def graded(n):
    xi = np.linspace(0.0, 1.0, n + 1)
    x = L * np.expm1(GRADING * xi) / np.expm1(GRADING)
    x[-1] = L
    return x


def destroy_mesh(mesh):
    if mesh.migration is not None:
        mesh.migration.destroy()
    mesh.dm.destroy()


def solve_theis(n, comm):
    serial, mask = None, None
    if comm.rank == 0:
        xs = graded(n)
        serial = box_mesh((L, L, B), (n, n, 1), xs=xs, ys=xs, zs=np.array([-B, 0.0]))
        mask = np.zeros(len(serial.points), np.int64)
        for name in ("xmax", "ymax"):
            mask[np.unique(serial.surfaces[name])] |= FIXED_HEAD_BIT
    mesh = distributed.build(comm, serial, vert_constraint=mask)
    flow = GroundwaterFlow(mesh, K, SS, wells=[(0.0, 0.0, 0.0, -B, Q / 4.0)], fixed_head=(mesh.vert_data[:, 0] & FIXED_HEAD_BIT) != 0,
                           substeps=2 * n)
    flow.advance_to(T_END)
    head = distributed.gather_vertex_values(mesh, flow.vertex_head()[:, None])
    its = sum(h["ksp_its"] for h in flow.history)
    flow.destroy()
    destroy_mesh(mesh)
    return serial, head, its


def theis(sizes, comm):
    out = {"n": sizes, "h_min": [], "max_rel_err": [], "radii": [], "rel_err_at": [], "ksp_its": []}
    for level, n in enumerate(sizes):
        serial, head, its = solve_theis(n, comm)
        if comm.rank != 0:
            continue
        x = serial.points
        r = np.hypot(x[:, 0], x[:, 1])
        s_fe = -head[:, 0]
        s_ex = fl.theis_drawdown(r, T_END, Q, K * B, SS * B)
        sel = (r >= R_MIN * (1 - 1e-9)) & (r <= R_MAX * (1 + 1e-9))
        rel = np.abs(s_fe[sel] - s_ex[sel]) / s_ex[sel]
        # on the symmetry line y = 0, the vertex nearest to each reporting radius
        on_axis = np.nonzero((x[:, 1] == 0.0) & (x[:, 2] == 0.0))[0]
        picks = [on_axis[np.argmin(np.abs(r[on_axis] - rr))] for rr in (20.0, 50.0, 100.0, 200.0)]
        out["h_min"].append(float(np.diff(graded(n))[0]))
        out["max_rel_err"].append(float(rel.max()))
        out["radii"].append([float(r[p]) for p in picks])
        out["rel_err_at"].append([float(abs(s_fe[p] - s_ex[p]) / s_ex[p]) for p in picks])
        out["ksp_its"].append(int(its))
        if level == 0:
            out["head_serial"] = head[:, 0].tolist()
    return out


def interface(comm):
    """Wells on the partition interface; settings through the -pfault_ options (read_flow_settings)."""
    from pfault.options import OptionReader
    from pfault.scene import Material
    from pfault.solver.flow import fixed_head_vertices, read_flow_settings
    mpi = comm.tompi4py()
    size, n = (120.0, 120.0, 12.0), (6, 6, 3)
    serial, mask = None, None
    if comm.rank == 0:
        serial = box_mesh(size, n, zs=np.linspace(-12.0, 0.0, 4))
    # a first distribution only to find where the interface is (the partition is deterministic)
    probe = distributed.build(comm, serial)
    x = probe.coords
    interior = (x[:, 0] > 0) & (x[:, 0] < size[0]) & (x[:, 1] > 0) & (x[:, 1] < size[1])
    shared = ~probe.vert_owned & interior if comm.size > 1 else interior
    key = np.where(shared, probe.vert_serial, np.iinfo(np.int64).max)
    best = mpi.allreduce((int(key.min()), comm.rank) if len(key) else (np.iinfo(np.int64).max, comm.rank),
                         op=MPI.MIN)
    xy = mpi.bcast(x[np.argmin(key), :2].tolist() if comm.rank == best[1] else None, root=best[1])
    destroy_mesh(probe)
    # well 1 on the vertical edge through that vertex, well 2 inside the vertical face x = xv
    wells_xy = [xy[0], xy[1], xy[0], xy[1] + 7.0]
    opts = PETSc.Options()
    opts.setValue("pfault_flow_wells", ",".join(f"{v!r}" for v in wells_xy))
    reader = OptionReader(PETSc)
    mats = [Material("soil", 1e7, 0.3, 1.0, 2000.0)]
    fs = read_flow_settings(reader, ["soil"], mats, ["xmin", "xmax", "ymin", "ymax", "bottom", "top"],
                            1000.0, 9.80665)
    if comm.rank == 0:
        mask = FIXED_HEAD_BIT * fixed_head_vertices(serial, fs.fixed_head_surfaces)
    mesh = distributed.build(comm, serial, vert_constraint=mask)
    cmat = mesh.cell_material
    flow = GroundwaterFlow(mesh, np.array(fs.conductivity)[cmat], np.array(fs.storage)[cmat], wells=fs.wells,
                           fixed_head=(mesh.vert_data[:, 0] & FIXED_HEAD_BIT) != 0, substeps=fs.substeps)
    out = {"wells": wells_xy, "load_sum": [], "load_diff_vs_serial": [], "storage": list(fs.storage),
           "conductivity": list(fs.conductivity), "rate_at_1day": fs.wells[0].rate(86400.0)}
    for well, load in zip(fs.wells, flow.wells.loads):
        out["load_sum"].append(load.sum())
        gathered = distributed.gather_vertex_values(mesh, flow.grid.to_local(load)[:, None])
        if comm.rank == 0:
            grad, vol = fl.tet_geometry(serial.points[serial.tets])
            length, mid = fl.vertical_line_in_tets(grad, vol, serial.points[serial.tets[:, 0]], well.x, well.y,
                                                   well.z_bottom, well.z_top)
            ref = np.bincount(serial.tets.ravel(), weights=(length[:, None] * mid).ravel(),
                              minlength=len(serial.points)) / (well.z_top - well.z_bottom)
            out["load_diff_vs_serial"].append(float(np.abs(gathered[:, 0] - ref).max()))
    flow.advance_to(0.5 * 86400.0)
    dp1 = flow.cell_dp()
    flow.advance_to(86400.0)
    dp2 = flow.cell_dp()
    flow.advance_to(86400.0)
    dp_again = flow.cell_dp()
    h = flow.vertex_head()
    out["dp_mean_check"] = mpi.allreduce(float(np.abs(dp2 - 1000.0 * 9.80665 * h[mesh.cells].mean(axis=1)).max()
                                               if len(dp2) else 0.0), op=MPI.MAX)
    out["dp_min"] = mpi.allreduce(float(dp2.min()) if len(dp2) else 0.0, op=MPI.MIN)
    out["dp_min_half_day"] = mpi.allreduce(float(dp1.min()) if len(dp1) else 0.0, op=MPI.MIN)
    out["repeat_identical"] = bool(mpi.allreduce(int(np.array_equal(dp2, dp_again)), op=MPI.MIN))
    out["history"] = [{k: v for k, v in h.items() if k != "ksp_its"} for h in flow.history]
    try:
        flow.advance_to(0.25 * 86400.0)
        out["went_back"] = True
    except ValueError:
        out["went_back"] = False
    flow.destroy()
    destroy_mesh(mesh)
    return out


def main():
    comm = PETSc.COMM_WORLD
    words = []
    for a in sys.argv[1:]:
        if a.startswith("-"):
            break
        words.append(a)
    if words[:1] == ["interface"]:
        out = interface(comm)
    else:
        out = theis([int(a) for a in words] or [24, 48], comm)
    if comm.rank == 0:
        print(json.dumps(out))


if __name__ == "__main__":
    main()
