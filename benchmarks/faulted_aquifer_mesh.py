#!/usr/bin/env python
"""Mesh of the faulted aquifer for config/faulted_aquifer.opts (gmsh MSH 4.1), in 3-D or as a plane-strain slab.

    .venv/bin/python benchmarks/faulted_aquifer_mesh.py runs/faulted_aquifer.msh [--size-factor 1]
    .venv/bin/python benchmarks/faulted_aquifer_mesh.py runs/faulted_aquifer_slab.msh --slab --fault-size 2

A 2 km x 1 km x 100 m block (x across the fault, y along its strike, z up, land surface at z = 0). A planar
fault crosses it from the land surface at x = 900 m to the bottom, dipping 40 degrees towards +x, and reaches
the ymin and ymax sides. The footwall (x below the fault) is rock; the hanging wall holds 30 m of clay over
70 m of sand down to the fixed bottom. Physical volumes: rock, clay, sand; physical surfaces: xmin, xmax, ymin,
ymax, bottom, top, fault (and contact: the welded part above a fault capped at --fault-top).

3-D: element size 12 m times --size-factor on the fault, growing to 48 m times the factor 150 m from it;
size factor 1 gives about 75,000 tetrahedra and 4,400 fault faces, 1.4 about 31,500, 2 about 13,300.
--strike-length L makes the block L m long along the strike instead: the same plane-strain problem on fewer
tetrahedra (40 m: 4,100 at size factor 1, 60,000 at 0.35).

--slab: the same x-z section as a slab one cell thick along the strike (its thickness the fault element
size), the plane-strain reference of the 3-D block once ymin and ymax are rollers: every node lies on one of
the two ends, so u_y = 0 everywhere. Element size --fault-size (m) on the fault, growing to 40 m 200 m from it.

--dip, --depth, --clay, --fault-x and --length change the geometry (defaults: 40 degrees, 100 m, 30 m, 900 m,
2000 m); --dip 90 makes the fault vertical (studies/queretaro_slab.py: Queretaro's section).
"""
import argparse
import math

import gmsh

L, W, D, X0, CLAY, DIP = 2000.0, 1000.0, 100.0, 900.0, 30.0, 40.0
FAULT_SIZE, FAR_SIZE, FAR_DIST = 9.2, 37.0, 150.0     # 3-D sizes at size factor 1 (m)


def fault_x(z):
    """x of the fault at height z (z <= 0)."""
    return X0 - z / math.tan(math.radians(DIP))


def _size_field(curves_or_surfaces, dim, h_fault, h_far, dist):
    f = gmsh.model.mesh.field
    f.add("Distance", 1)
    f.setNumbers(1, "SurfacesList" if dim == 2 else "CurvesList", curves_or_surfaces)
    f.setNumber(1, "Sampling", 200)
    f.add("Threshold", 2)
    f.setNumber(2, "InField", 1)
    f.setNumber(2, "SizeMin", h_fault)
    f.setNumber(2, "SizeMax", h_far)
    f.setNumber(2, "DistMin", 0.5 * h_fault)
    f.setNumber(2, "DistMax", dist)
    f.setAsBackgroundMesh(2)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)


def _name_volumes(vols):
    groups = {"rock": [], "clay": [], "sand": []}
    for v in vols:
        x, _, z = gmsh.model.occ.getCenterOfMass(3, v)
        if x < fault_x(z):
            groups["rock"].append(v)
        else:
            groups["clay" if z > -CLAY else "sand"].append(v)
    for name, tags in groups.items():
        gmsh.model.addPhysicalGroup(3, tags, name=name)


def _name_surfaces(fault_top):
    groups = {k: [] for k in ("xmin", "xmax", "ymin", "ymax", "bottom", "top", "fault", "contact")}
    tol = 1e-6
    for _, s in gmsh.model.getEntities(2):
        x, y, z = gmsh.model.occ.getCenterOfMass(2, s)
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, s)
        flat_x, flat_y, flat_z = x1 - x0 < tol, y1 - y0 < tol, z1 - z0 < tol
        if flat_x and (abs(x) < tol or abs(x - L) < tol):
            groups["xmin" if abs(x) < tol else "xmax"].append(s)
        elif flat_y:
            groups["ymin" if abs(y) < tol else "ymax"].append(s)
        elif flat_z and abs(z + D) < tol:
            groups["bottom"].append(s)
        elif flat_z and abs(z) < tol:
            groups["top"].append(s)
        elif not flat_z:
            groups["contact" if z > -fault_top else "fault"].append(s)
    for name, tags in groups.items():
        if tags:
            gmsh.model.addPhysicalGroup(2, tags, name=name)
    return groups


def _plane(occ, z0, z1, e):
    """The fault plane between heights z0 > z1, overhanging the block's ends by e."""
    p = [occ.addPoint(fault_x(z0), -e, z0), occ.addPoint(fault_x(z0), W + e, z0),
         occ.addPoint(fault_x(z1), W + e, z1), occ.addPoint(fault_x(z1), -e, z1)]
    return occ.addPlaneSurface([occ.addCurveLoop([occ.addLine(p[i], p[(i + 1) % 4]) for i in range(4)])])


def build_3d(size_factor, fault_top=0.0):
    occ = gmsh.model.occ
    box = occ.addBox(0, 0, -D, L, W, D)
    e = 50.0       # the cutting surfaces overhang the block
    cuts = [(2, _plane(occ, e if fault_top == 0 else -fault_top, -D - e, e))]
    if fault_top > 0:
        cuts.append((2, _plane(occ, e, -fault_top, e)))       # the welded rock-sediment contact above the fault
    base = occ.addRectangle(fault_x(-CLAY), -e, -CLAY, L, W + 2 * e)     # clay/sand interface, hanging wall only
    occ.fragment([(3, box)], cuts + [(2, base)])
    occ.synchronize()
    vols = [t for _, t in gmsh.model.getEntities(3)]
    bounding = {s for v in vols for _, s in gmsh.model.getBoundary([(3, v)], oriented=False)}
    gmsh.model.removeEntities([(2, s) for _, s in gmsh.model.getEntities(2) if s not in bounding], recursive=True)
    _name_volumes(vols)
    groups = _name_surfaces(fault_top)
    _size_field(groups["fault"] + groups["contact"], 2, FAULT_SIZE * size_factor, FAR_SIZE * size_factor, FAR_DIST)
    gmsh.model.mesh.generate(3)


def build_slab(fault_size, fault_top=0.0, far_size=40.0, far_dist=200.0):
    occ = gmsh.model.occ
    # the x-z section drawn in the x-y plane (y standing for z), turned into the x-z plane below
    rect = occ.addRectangle(0, -D, 0, L, D)
    e = 10.0
    z0 = e if fault_top == 0 else -fault_top
    cuts = [(1, occ.addLine(occ.addPoint(fault_x(z0), z0, 0), occ.addPoint(fault_x(-D - e), -D - e, 0)))]
    if fault_top > 0:
        cuts.append((1, occ.addLine(occ.addPoint(fault_x(e), e, 0), occ.addPoint(fault_x(z0), z0, 0))))
    b0, b1 = occ.addPoint(fault_x(-CLAY), -CLAY, 0), occ.addPoint(L + e, -CLAY, 0)
    base = occ.addLine(b0, b1)
    occ.fragment([(2, rect)], cuts + [(1, base)])
    occ.synchronize()
    surfs = [t for _, t in gmsh.model.getEntities(2)]
    bounding = {c for s in surfs for _, c in gmsh.model.getBoundary([(2, s)], oriented=False)}
    gmsh.model.removeEntities([(1, c) for _, c in gmsh.model.getEntities(1) if c not in bounding], recursive=True)
    occ.rotate([(2, s) for s in surfs], 0, 0, 0, 1, 0, 0, math.pi / 2)
    occ.synchronize()
    fault_curves = []        # the fault's (and the welded contact's) curves: not horizontal, not the sides
    for _, c in gmsh.model.getEntities(1):
        x0, _, z0, x1, _, z1 = gmsh.model.getBoundingBox(1, c)
        side = x1 - x0 < 1e-6 and (abs(x0) < 1e-6 or abs(x0 - L) < 1e-6)
        if z1 - z0 > 1e-6 and not side:
            fault_curves.append(c)
    _size_field(fault_curves, 1, fault_size, max(far_size, fault_size), far_dist)
    gmsh.model.mesh.generate(2)
    # one layer of tetrahedra (extruded prisms, split) of thickness the fault element size
    occ.extrude([(2, s) for s in surfs], 0, fault_size, 0, numElements=[1], recombine=False)
    occ.synchronize()
    vols = [t for _, t in gmsh.model.getEntities(3)]
    _name_volumes(vols)
    _name_surfaces(fault_top)
    gmsh.model.mesh.generate(3)


def build(out, size_factor=1.0, slab=False, fault_size=2.0, fault_top=0.0, strike_length=None, dip=None,
          depth=None, clay=None, fault_x0=None, length=None):
    global W, DIP, D, CLAY, X0, L
    if strike_length is not None:
        W = strike_length
    DIP = DIP if dip is None else dip
    D = D if depth is None else depth
    CLAY = CLAY if clay is None else clay
    X0 = X0 if fault_x0 is None else fault_x0
    L = L if length is None else length
    gmsh.initialize(["faulted_aquifer_mesh"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        if slab:
            build_slab(fault_size, fault_top)
        else:
            build_3d(size_factor, fault_top)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(out)
        return len(gmsh.model.mesh.getElementsByType(4)[0])
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--size-factor", type=float, default=1.0, help="multiplies every element size (3-D)")
    ap.add_argument("--slab", action="store_true", help="the plane-strain slab instead of the 3-D block")
    ap.add_argument("--fault-size", type=float, default=2.0, help="slab: element size on the fault (m)")
    ap.add_argument("--fault-top", type=float, default=0.0, help="depth of the fault's upper edge (m); above "
                    "it the rock-sediment contact is welded (physical surface contact, not split)")
    ap.add_argument("--strike-length", type=float, default=None, help="3-D: length of the block along the strike "
                    "(m, default 1000): a shorter block is the same plane-strain problem on fewer tetrahedra")
    ap.add_argument("--dip", type=float, default=None, help="the fault's dip (degrees, default 40; 90: vertical)")
    ap.add_argument("--depth", type=float, default=None, help="the block's depth (m, default 100)")
    ap.add_argument("--clay", type=float, default=None, help="the clay's thickness in the hanging wall (m, default 30)")
    ap.add_argument("--fault-x", type=float, default=None, help="x of the fault at the land surface (m, default 900)")
    ap.add_argument("--length", type=float, default=None, help="the block's length across the fault (m, default 2000)")
    a = ap.parse_args()
    n = build(a.out, a.size_factor, a.slab, a.fault_size, a.fault_top, a.strike_length, a.dip, a.depth, a.clay,
              a.fault_x, a.length)
    print(f"{a.out}: {n} tetrahedra")
