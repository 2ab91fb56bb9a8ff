#!/usr/bin/env python
"""Frictional crack in compression and shear (plane strain): slab mesh, exact slip and error measures.

A straight crack of half-length a, z = 0, |x| < a, in the square [-L, L] x [-L, L] of the x-z plane, as a slab
one element thick along y (its thickness the crack's element size h = a/n; rollers on y = 0 and y = h make it
plane strain). The section is meshed in 2-D and extruded as one layer of prisms, each split into three
tetrahedra; the crack's tips x = +-a are edges through the slab whose vertices are not split.

Physical names: volume ``solid``; surfaces ``crack``, ``bottom`` (z = -L), ``top`` (z = L), ``xmin``, ``xmax``
(x = -+L), ``ymin``, ``ymax`` (the slab's faces y = 0 and y = h).

Element sizes: h = a/n within 0.25 a of the crack, growing beyond as h * 1.2 d/a with the distance d, capped at
L/4 (as tests/scripts/penny_mesh.py, so that the meshes are self-similar in n).

Exact slip (the Griffith crack's opening with the shear stress drop in place of the tension, e.g. Pollard & Segall
1987, "Theoretical displacements and stresses near fractures in rock"): a cohesionless crack with friction
coefficient f under remote normal compression sigma_n and shear tau > f sigma_n slips over its whole length, the
shear traction on it f sigma_n, and
    s(x) = 4 (1 - nu^2) / E * (tau - f sigma_n) * sqrt(a^2 - x^2)      (plane strain).
The normal traction stays sigma_n (shear slip on a straight crack in a homogeneous body does not change it).

Used by benchmarks/frictional_crack.py and tests/verification/test_frictional_crack.py (``make_crack_mesh``,
``exact_slip``, ``slip_errors``), and from the command line:

    .venv/bin/python tests/scripts/frictional_crack_mesh.py OUT.msh [--a 1] [--L 10] [--n 8]

prints a JSON line {"path", "nodes", "tets", "crack_triangles", "h"}.
"""
import argparse
import json
import math

import numpy as np

GRADE = 1.2          # size growth per crack half-length of distance, in units of h
FINE_ZONE = 0.25     # crack half-lengths around the crack meshed at h


def make_crack_mesh(path, a=1.0, L=10.0, n=8):
    """Write the slab mesh (MSH 4.1) to ``path``; return its sizes."""
    import gmsh

    from gmsh_session import gmsh_session, write_msh41

    h = a / n
    h_far = L / 4.0
    slope = GRADE * h / a
    with gmsh_session("frictional-crack-mesh"):
        gmsh.model.add("frictional_crack")
        occ = gmsh.model.occ
        # the x-z section drawn in the x-y plane (y standing for z), turned into the x-z plane below
        rect = occ.addRectangle(-L, -L, 0.0, 2.0 * L, 2.0 * L)
        # the plane z = 0 cut across the section (the crack and its welded extensions), so that the crack lies
        # between two surfaces and its extruded triangles are faces of the tetrahedra on both sides
        pts = [occ.addPoint(x, 0.0, 0.0) for x in (-L, -a, a, L)]
        cuts = [(1, occ.addLine(p, q)) for p, q in zip(pts[:-1], pts[1:])]
        out, _ = occ.fragment([(2, rect)], cuts)
        surfs = [t for d, t in out if d == 2]
        occ.rotate([(2, s) for s in surfs], 0, 0, 0, 1, 0, 0, math.pi / 2)
        occ.synchronize()
        tol = 1e-6 * L        # OCC bounding boxes are enlarged by the geometric tolerance
        crack_curves = []
        for _, c in gmsh.model.getEntities(1):
            x0, _, z0, x1, _, z1 = gmsh.model.getBoundingBox(1, c)
            if abs(z0) < tol and abs(z1) < tol and x0 > -a - tol and x1 < a + tol:
                crack_curves.append(c)
        if len(crack_curves) != 1:
            raise RuntimeError(f"frictional crack mesh: expected one crack curve, got {crack_curves}")

        field = gmsh.model.mesh.field
        dist = field.add("Distance")
        field.setNumbers(dist, "CurvesList", crack_curves)
        field.setNumber(dist, "Sampling", max(100, 20 * n))
        thr = field.add("Threshold")
        field.setNumber(thr, "InField", dist)
        field.setNumber(thr, "SizeMin", h)
        field.setNumber(thr, "SizeMax", h_far)
        field.setNumber(thr, "DistMin", FINE_ZONE * a)
        field.setNumber(thr, "DistMax", FINE_ZONE * a + (h_far - h) / slope)
        field.setAsBackgroundMesh(thr)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.model.mesh.generate(2)
        # one layer of tetrahedra (extruded prisms, split) of thickness h
        occ.extrude([(2, s) for s in surfs], 0, h, 0, numElements=[1], recombine=False)
        occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [t for _, t in gmsh.model.getEntities(3)], name="solid")
        tol = 1e-3 * h
        groups = {}
        for _, s in gmsh.model.getEntities(2):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, s)
            if y1 < tol:
                name = "ymin"
            elif y0 > h - tol:
                name = "ymax"
            elif x1 < -L + tol:
                name = "xmin"
            elif x0 > L - tol:
                name = "xmax"
            elif z1 < -L + tol:
                name = "bottom"
            elif z0 > L - tol:
                name = "top"
            elif abs(z0) < tol and abs(z1) < tol:
                name = "crack" if x0 > -a - tol and x1 < a + tol else "welded"
            else:
                raise RuntimeError(f"frictional crack mesh: surface {s} is none of the expected ones")
            groups.setdefault(name, []).append(s)
        if set(groups) != {"xmin", "xmax", "ymin", "ymax", "bottom", "top", "crack", "welded"}:
            raise RuntimeError(f"frictional crack mesh: unexpected surfaces {groups}")
        del groups["welded"]
        for name, tags in groups.items():
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        gmsh.model.mesh.generate(3)
        tets = len(gmsh.model.mesh.getElementsByType(4)[0])
        tris = sum(len(gmsh.model.mesh.getElementsByType(2, s)[0]) for s in groups["crack"])
        nodes = len(gmsh.model.mesh.getNodes()[0])
        write_msh41(gmsh, path)
    return {"path": str(path), "nodes": int(nodes), "tets": int(tets), "crack_triangles": int(tris), "h": h}


def exact_slip(x, a, young, nu, stress_drop):
    """s(x) = 4 (1 - nu^2) / E * stress_drop * sqrt(a^2 - x^2), zero outside the crack."""
    return 4.0 * (1.0 - nu ** 2) / young * stress_drop * np.sqrt(np.maximum(a ** 2 - np.asarray(x) ** 2, 0.0))


def face_mean_exact(tri_x, a, young, nu, stress_drop, order=40):
    """The exact slip averaged over each triangle (its corners tri_x, shape (m, 3, 3)): the slip depends on x
    only, so the average is that of s over the triangle's x-extent weighted by the triangle's width at x,
    integrated with ``order`` Gauss points on each of the two pieces either side of the middle vertex."""
    xs = np.sort(tri_x[:, :, 0], axis=1)
    g, w = np.polynomial.legendre.leggauss(order)
    integral = np.zeros(len(xs))
    for lo, hi, rising in ((xs[:, 0], xs[:, 1], True), (xs[:, 1], xs[:, 2], False)):
        # the triangle's width across x is linear on each piece: 0 at the outer vertex, 1 (scaled) at the middle
        half = 0.5 * (hi - lo)
        xq = 0.5 * (hi + lo)[:, None] + half[:, None] * g[None, :]
        frac = 0.5 * (1.0 + g)[None, :]
        width = frac if rising else 1.0 - frac
        integral += np.sum(w[None, :] * half[:, None] * width * exact_slip(xq, a, young, nu, stress_drop), axis=1)
    return integral / (0.5 * (xs[:, 2] - xs[:, 0]))


def slip_errors(tri_x, slip, a, young, nu, stress_drop):
    """Errors of face-wise slips ``slip`` (the x component of the jump, averaged over each crack triangle with
    corners ``tri_x``) against the exact face averages: the area-weighted L2 error relative to the exact slip's
    L2 norm over the crack, the largest face error relative to the largest slip s(0), the error of the largest face
    slip against s(0) and that of the potency (the slip's integral over the crack)."""
    tri_x = np.asarray(tri_x, dtype=float)
    area = 0.5 * np.linalg.norm(np.cross(tri_x[:, 1] - tri_x[:, 0], tri_x[:, 2] - tri_x[:, 0]), axis=1)
    exact = face_mean_exact(tri_x, a, young, nu, stress_drop)
    s0 = float(exact_slip(0.0, a, young, nu, stress_drop))
    err = np.asarray(slip, dtype=float) - exact
    return {"s0": s0, "faces": int(len(tri_x)), "crack_area": float(area.sum()),
            "l2_error": float(np.sqrt(np.sum(area * err ** 2) / np.sum(area * exact ** 2))),
            "max_error": float(np.max(np.abs(err)) / s0),
            "max_slip_error": float(np.max(slip) / s0 - 1.0),
            "potency_error": float(np.sum(area * slip) / np.sum(area * exact) - 1.0)}


def read_pfault_slip(outdir):
    """Crack triangles' corners, slip (x component of the jump, its sign such that the crack's mean is
    positive), the rest of the last step's fields of ``outdir``/fault.h5."""
    import os

    import h5py
    with h5py.File(os.path.join(str(outdir), "fault.h5"), "r") as f:
        pts, cells = f["mesh/points"][()], f["mesh/cells"][()]
        last = f["steps"][sorted(f["steps"].keys())[-1]]
        fields = {k: last[k][()] for k in last.keys()}
    sx = fields["slip"][:, 0]
    return pts[cells], sx * np.sign(np.sum(sx)), fields


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("path")
    p.add_argument("--a", type=float, default=1.0, help="crack half-length (m)")
    p.add_argument("--L", type=float, default=10.0, help="half-side of the square section (m)")
    p.add_argument("--n", type=int, default=8, help="element size at the crack is a/n")
    args = p.parse_args(argv)
    print(json.dumps(make_crack_mesh(args.path, args.a, args.L, args.n)))


if __name__ == "__main__":
    main()
