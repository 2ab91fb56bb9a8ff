#!/usr/bin/env python
"""Penny-shaped crack under remote tension (Sneddon): quarter-model gmsh mesh and error measures.

Domain [0,L] x [0,L] x [-L,L]; the crack is the quarter disk x^2 + y^2 < a^2, z = 0, x, y >= 0,
embedded in the volume (OCC fragment) so that each of its triangles is shared by two tetrahedra.
Its curved edge is buried in the solid (crack tip: unsplit vertices); its straight edges lie on the
symmetry planes x = 0 and y = 0 (split vertices, roller conditions there).

Physical names: volume ``solid``; surfaces ``xmin``, ``ymin`` (symmetry planes), ``bottom`` (z = -L),
``top`` (z = L), ``xmax``, ``ymax`` (far sides), ``crack``.

Element sizes, all proportional to 1/n up to the far-field cap: h_c = a/n within 0.25 a of the crack,
h_c/3 at the crack tip (within 0.05 a of the curved edge), growing with the distance d beyond those
zones as h_c * 1.2 d/a, capped at L/4.

Used by tests/verification/test_crack.py and benchmarks/penny_crack.py (``make_penny_mesh``, ``crack_errors``), and
from the command line:

    .venv/bin/python tests/scripts/penny_mesh.py OUT.msh [--a 1] [--L 8] [--n 8]

prints a JSON line {"path", "nodes", "tets", "crack_triangles"}.
"""
import argparse
import json
import os

import numpy as np

GRADE = 1.2          # size growth per crack radius of distance, in units of h_c
FINE_ZONE = 0.25     # crack radii around the crack meshed at h_c
TIP_FACTOR = 1.0 / 3.0
TIP_ZONE = 0.05      # crack radii around the tip meshed at TIP_FACTOR * h_c


def make_penny_mesh(path, a=1.0, L=8.0, n=8):
    """Write the quarter penny-crack mesh (MSH 4.1) to ``path``; return its sizes."""
    import gmsh

    from gmsh_session import gmsh_session, write_msh41

    h_crack = a / n
    h_tip = TIP_FACTOR * h_crack
    h_far = L / 4.0
    slope = GRADE * h_crack / a
    with gmsh_session("penny-mesh"):
        gmsh.model.add("penny")
        occ = gmsh.model.occ
        box = occ.addBox(0.0, 0.0, -L, L, L, 2.0 * L)
        c = occ.addPoint(0.0, 0.0, 0.0)
        px = occ.addPoint(a, 0.0, 0.0)
        py = occ.addPoint(0.0, a, 0.0)
        lx = occ.addLine(c, px)
        arc = occ.addCircleArc(px, c, py)
        ly = occ.addLine(py, c)
        disk = occ.addPlaneSurface([occ.addCurveLoop([lx, arc, ly])])
        out, out_map = occ.fragment([(3, box)], [(2, disk)])
        occ.synchronize()

        vols = [t for d, t in out if d == 3]
        if len(vols) != 1:
            raise RuntimeError(f"penny mesh: expected one volume after the fragment, got {len(vols)}")
        gmsh.model.addPhysicalGroup(3, vols, name="solid")
        tol = 1e-6 * L     # OCC bounding boxes are enlarged by the geometric tolerance
        groups = {}
        for _, s in gmsh.model.getEntities(2):
            xmin, ymin, zmin, xmax, ymax, zmax = gmsh.model.getBoundingBox(2, s)
            if xmax < tol:
                name = "xmin"
            elif ymax < tol:
                name = "ymin"
            elif xmin > L - tol:
                name = "xmax"
            elif ymin > L - tol:
                name = "ymax"
            elif zmax < -L + tol:
                name = "bottom"
            elif zmin > L - tol:
                name = "top"
            elif abs(zmin) < tol and abs(zmax) < tol:
                name = "crack"
            else:
                raise RuntimeError(f"penny mesh: surface {s} is none of the expected ones")
            groups.setdefault(name, []).append(s)
        expected = {"xmin", "ymin", "xmax", "ymax", "bottom", "top", "crack"}
        if set(groups) != expected or any(len(v) != 1 for v in groups.values()):
            raise RuntimeError(f"penny mesh: unexpected surfaces {groups}")
        for name, tags in groups.items():
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        crack_curves = [t for _, t in gmsh.model.getBoundary([(2, groups["crack"][0])], oriented=False)]
        tip_curves = [t for t in crack_curves if abs(gmsh.model.occ.getMass(1, t) - 0.5 * np.pi * a) < 1e-6 * a]
        if len(tip_curves) != 1:
            raise RuntimeError(f"penny mesh: cannot find the crack tip among curves {crack_curves}")

        # sizes: h_crack near the crack, h_tip at its tip, both growing linearly with the distance
        field = gmsh.model.mesh.field

        def threshold(dist, size):
            f = field.add("Threshold")
            field.setNumber(f, "InField", dist[0])
            field.setNumber(f, "SizeMin", size)
            field.setNumber(f, "SizeMax", h_far)
            field.setNumber(f, "DistMin", dist[1])
            field.setNumber(f, "DistMax", dist[1] + (h_far - size) / slope)
            return f

        d_crack = field.add("Distance")
        field.setNumbers(d_crack, "SurfacesList", groups["crack"])
        field.setNumbers(d_crack, "CurvesList", crack_curves)
        field.setNumber(d_crack, "Sampling", max(40, 8 * n))
        d_tip = field.add("Distance")
        field.setNumbers(d_tip, "CurvesList", tip_curves)
        field.setNumber(d_tip, "Sampling", max(100, 40 * n))
        fmin = field.add("Min")
        field.setNumbers(fmin, "FieldsList", [threshold((d_crack, FINE_ZONE * a), h_crack),
                                              threshold((d_tip, TIP_ZONE * a), h_tip)])
        field.setAsBackgroundMesh(fmin)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)        # Delaunay
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)

        tets = len(gmsh.model.mesh.getElementsByType(4)[0])
        tris = len(gmsh.model.mesh.getElementsByType(2, groups["crack"][0])[0])
        nodes = len(gmsh.model.mesh.getNodes()[0])
        write_msh41(gmsh, path)
    return {"path": str(path), "nodes": int(nodes), "tets": int(tets), "crack_triangles": int(tris)}


def sneddon_opening(r, a, young, nu, sigma):
    """Exact opening w(r) = 8 (1 - nu^2) sigma / (pi E) sqrt(a^2 - r^2) (zero outside the crack)."""
    return 8.0 * (1.0 - nu ** 2) * sigma / (np.pi * young) * np.sqrt(np.maximum(a ** 2 - np.asarray(r) ** 2, 0.0))


def read_fault_step(outdir, step=-1):
    """Points, triangles and cell data of one step of ``fault.xdmf`` (default: the last)."""
    import meshio
    reader = meshio.xdmf.TimeSeriesReader(os.path.join(str(outdir), "fault.xdmf"))
    points, cells = reader.read_points_cells()
    k = reader.num_steps + step if step < 0 else step
    _, _, cell_data = reader.read_data(k)
    tri = np.concatenate([c.data for c in cells if c.type == "triangle"])
    return points, tri, {name: v[0] for name, v in cell_data.items()}


def crack_errors(outdir, a=1.0, young=10e9, nu=0.25, sigma=1e6):
    """Face-wise opening of the run in ``outdir`` against Sneddon's solution.

    max_error: (largest face opening - w0)/w0; centre_error: error of the face nearest to r = 0 against
    w at its centroid; rms_error: area-weighted RMS over the crack of (opening - w(centroid radius)),
    divided by w0. Openings are face averages of the P1 jump, compared at the face centroid.
    """
    points, tri, cd = read_fault_step(outdir)
    x = points[tri]
    centroid = x.mean(axis=1)
    r = np.hypot(centroid[:, 0], centroid[:, 1])
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    w0 = float(sneddon_opening(0.0, a, young, nu, sigma))
    exact = sneddon_opening(r, a, young, nu, sigma)
    opening = np.asarray(cd["opening"], dtype=float)
    centre = int(np.argmin(r))
    return {"w0": w0, "faces": int(len(tri)), "max_opening": float(opening.max()),
            "max_error": float(opening.max() / w0 - 1.0),
            "centre_error": float(opening[centre] / exact[centre] - 1.0),
            "rms_error": float(np.sqrt(np.sum(area * (opening - exact) ** 2) / np.sum(area)) / w0),
            "crack_area": float(area.sum()), "states": np.bincount(cd["state"], minlength=3).tolist(),
            "centroid_radius": r, "opening": opening}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("path")
    p.add_argument("--a", type=float, default=1.0, help="crack radius (m)")
    p.add_argument("--L", type=float, default=8.0, help="side of the quarter domain, half its height (m)")
    p.add_argument("--n", type=int, default=8, help="element size at the crack is a/n")
    args = p.parse_args(argv)
    print(json.dumps(make_penny_mesh(args.path, args.a, args.L, args.n)))


if __name__ == "__main__":
    main()
