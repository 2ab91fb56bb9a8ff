#!/usr/bin/env python
"""Mesh of a basin-bounding normal fault for config/basin_fault.opts (gmsh MSH 4.1).

    .venv/bin/python benchmarks/basin_fault_mesh.py runs/basin_fault.msh [--size 95] [--dip 60] [--layers 60,240]

A 3 km x 1.5 km x 600 m block. A planar fault crosses it from the land surface at x = 1200 m to the bottom,
dipping --dip degrees towards +x, and reaches the four other boundaries it meets. The hanging wall (beyond the
fault) holds 300 m of basin sediments (material `basin`) over rock; the footwall is rock. With --layers (depths
in m, within the sediments) the sediments are layers `basin1`, `basin2`, ... from the top, split at those
depths. Physical surfaces: xmin, xmax, ymin, ymax, bottom, top, fault. Element size --size (m) away from the
fault, half of it within one size of the fault: 95 m gives about 37,000 tetrahedra and 1,150 fault faces.
"""
import argparse
import math

import gmsh

L, W, D, X0, SED = 3000.0, 1500.0, 600.0, 1200.0, 300.0


def build(out, size, dip, layers=()):
    cot = 1.0 / math.tan(math.radians(dip))

    def fault_x(z):
        return X0 - z * cot

    gmsh.initialize(["basin_fault_mesh"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        occ = gmsh.model.occ
        box = occ.addBox(0, 0, -D, L, W, D)
        e = 100.0      # the cutting surfaces overhang the block
        p = [occ.addPoint(fault_x(e), -e, e), occ.addPoint(fault_x(e), W + e, e),
             occ.addPoint(fault_x(-D - e), W + e, -D - e), occ.addPoint(fault_x(-D - e), -e, -D - e)]
        fault = occ.addPlaneSurface([occ.addCurveLoop([occ.addLine(p[i], p[(i + 1) % 4]) for i in range(4)])])
        depths = sorted(set(layers) | {SED})
        cuts = [occ.addRectangle(-e, -e, -d, L + 2 * e, W + 2 * e) for d in depths]
        occ.fragment([(3, box)], [(2, fault)] + [(2, c) for c in cuts])
        occ.synchronize()
        vols = [t for _, t in gmsh.model.getEntities(3)]
        bounding = {s for v in vols for _, s in gmsh.model.getBoundary([(3, v)], oriented=False)}
        gmsh.model.removeEntities([(2, s) for _, s in gmsh.model.getEntities(2) if s not in bounding], recursive=True)
        rock, basin = [], [[] for _ in depths]
        for v in vols:
            x, _, z = occ.getCenterOfMass(3, v)
            if x > fault_x(z) and z > -SED:
                basin[sum(-z > d for d in depths)].append(v)
            else:
                rock.append(v)
        gmsh.model.addPhysicalGroup(3, rock, name="rock")
        names = ["basin"] if len(depths) == 1 else [f"basin{k + 1}" for k in range(len(depths))]
        for name, tags in zip(names, basin):
            gmsh.model.addPhysicalGroup(3, tags, name=name)
        groups = {k: [] for k in ("xmin", "xmax", "ymin", "ymax", "bottom", "top", "fault")}
        tol = 1e-6
        for _, s in gmsh.model.getEntities(2):
            x, y, z = occ.getCenterOfMass(2, s)
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, s)
            flat_x, flat_y, flat_z = x1 - x0 < tol, y1 - y0 < tol, z1 - z0 < tol
            if flat_x:
                groups["xmin" if abs(x) < tol else "xmax"].append(s)
            elif flat_y:
                groups["ymin" if abs(y) < tol else "ymax"].append(s)
            elif flat_z and abs(z + D) < tol:
                groups["bottom"].append(s)
            elif flat_z and abs(z) < tol:
                groups["top"].append(s)
            elif not flat_z:
                groups["fault"].append(s)
        for name, tags in groups.items():
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        f = gmsh.model.mesh.field
        f.add("Distance", 1)
        f.setNumbers(1, "SurfacesList", groups["fault"])
        f.add("Threshold", 2)
        f.setNumber(2, "InField", 1)
        f.setNumber(2, "SizeMin", size / 2)
        f.setNumber(2, "SizeMax", size)
        f.setNumber(2, "DistMin", size)
        f.setNumber(2, "DistMax", 6 * size)
        f.setAsBackgroundMesh(2)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(out)
        return len(gmsh.model.mesh.getElementsByType(4)[0])
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--size", type=float, default=95.0, help="element size away from the fault (m)")
    ap.add_argument("--dip", type=float, default=60.0, help="fault dip (degrees)")
    ap.add_argument("--layers", default="", help="depths (m) splitting the basin sediments into layers, e.g. 60,240")
    a = ap.parse_args()
    layers = [float(v) for v in a.layers.split(",") if v.strip()]
    if any(not 0.0 < d < SED for d in layers):
        raise SystemExit(f"--layers: depths between 0 and {SED:g} m (the sediments' base)")
    print(f"{a.out}: {build(a.out, a.size, a.dip, layers)} tetrahedra")
