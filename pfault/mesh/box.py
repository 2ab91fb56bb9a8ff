"""Structured tetrahedral box: hexahedra split into six Kuhn tetrahedra, layered materials."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from .serial import SerialMesh, boundary_faces, orient_positive, TET_FACES

# Kuhn (Freudenthal) subdivision: every tet follows a path 000 -> 111 along the cube edges
_PERMS = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]


def _kuhn_corners():
    tets = []
    for p in _PERMS:
        corner = np.zeros(3, int)
        path = [corner.copy()]
        for axis in p:
            corner[axis] = 1
            path.append(corner.copy())
        tets.append([c[0] + 2 * c[1] + 4 * c[2] for c in path])
    return np.array(tets)


def layer_z_nodes(lz: float, nz: int, interfaces: Sequence[float]) -> np.ndarray:
    """z-coordinates of node planes from -lz to 0 with planes at every interface depth."""
    depths = [0.0] + sorted(interfaces) + [lz]
    if any(b <= a for a, b in zip(depths, depths[1:])):
        raise InputError("-pfault_box_interfaces: depths must lie strictly between 0 and the box height "
                         "and increase")
    thick = np.diff(depths)
    n = np.maximum(1, np.round(nz * thick / lz).astype(int))
    zs = [np.array([0.0])]
    for d0, d1, k in zip(depths[:-1], depths[1:], n):
        zs.append(-np.linspace(d0, d1, k + 1)[1:])
    return np.concatenate(zs)[::-1]  # increasing


def parse_planes(specs: Iterable[str]) -> list[tuple[str, int, float, list[float]]]:
    """'name:axis:value[:lo1:hi1:lo2:hi2]' -> (name, axis, value, bounds of the two other coordinates)."""
    planes = []
    for spec in specs:
        parts = spec.split(":")
        if len(parts) not in (3, 7) or parts[1] not in ("x", "y", "z"):
            raise InputError(f"-pfault_box_fault_planes: '{spec}' is not name:axis:value[:lo1:hi1:lo2:hi2] "
                             "(example: fault:x:500)")
        try:
            nums = [float(v) for v in parts[2:]]
        except ValueError:
            raise InputError(f"-pfault_box_fault_planes: '{spec}' has a value that is not a number") from None
        bounds = nums[1:] if len(nums) == 5 else [-np.inf, np.inf, -np.inf, np.inf]
        planes.append((parts[0], "xyz".index(parts[1]), nums[0], bounds))
    return planes


def _node_planes(size, cells, interfaces, xs, ys, zs, planes):
    """The node coordinates along x, y and z (given, or uniform with planes at the interface depths), each with
    the fault planes across it added."""
    lx, ly, lz = size
    nx, ny, nz = cells
    xs = np.linspace(0.0, lx, nx + 1) if xs is None else np.asarray(xs, float)
    ys = np.linspace(0.0, ly, ny + 1) if ys is None else np.asarray(ys, float)
    zs = layer_z_nodes(lz, nz, list(interfaces)) if zs is None else np.asarray(zs, float)
    grids = [xs, ys, zs]
    for name, axis, value, _ in planes:
        g = grids[axis]
        if not g[0] < value < g[-1]:
            raise InputError(f"-pfault_box_fault_planes: plane '{name}' at {value} is not inside the box")
        grids[axis] = np.unique(np.concatenate([g, [value]]))
    return grids


def _kuhn_tets(xs, ys, zs):
    """Points and positively oriented tetrahedra: six Kuhn tetrahedra per hexahedron of the grid."""
    nx, ny, nz = len(xs) - 1, len(ys) - 1, len(zs) - 1
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])

    def vid(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    corners = np.stack([vid(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)) for c in range(8)], axis=1)
    tets = corners[:, _kuhn_corners()].reshape(-1, 4)
    return points, orient_positive(points, tets)


def _outer_surfaces(points, tets, grids, tol):
    """The six sides' boundary triangles: {xmin, xmax, ymin, ymax, bottom, top: (nf, 3)}."""
    xs, ys, zs = grids
    cell, lface = boundary_faces(tets, len(points))
    tri = tets[cell[:, None], TET_FACES[lface]]
    c = points[tri].mean(axis=1)
    surfaces = {}
    for name, mask in (("xmin", np.abs(c[:, 0] - xs[0]) < tol), ("xmax", np.abs(c[:, 0] - xs[-1]) < tol),
                       ("ymin", np.abs(c[:, 1] - ys[0]) < tol), ("ymax", np.abs(c[:, 1] - ys[-1]) < tol),
                       ("bottom", np.abs(c[:, 2] - zs[0]) < tol), ("top", np.abs(c[:, 2] - zs[-1]) < tol)):
        surfaces[name] = tri[mask]
    return surfaces


def _plane_surfaces(points, tets, planes, grids, tol):
    """Each fault plane's interior triangles within its bounds: {name: (nf, 3)}."""
    faces = tets[:, TET_FACES].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    key = (key[:, 0] * len(points) + key[:, 1]) * len(points) + key[:, 2]
    ukey, first = np.unique(key, return_index=True)
    faces = faces[first]
    fx = points[faces]
    surfaces = {}
    for name, axis, value, bounds in planes:
        on = np.all(np.abs(fx[:, :, axis] - value) < tol, axis=1)
        o = [a for a in range(3) if a != axis]
        c = fx.mean(axis=1)
        inside = ((c[:, o[0]] > bounds[0]) & (c[:, o[0]] < bounds[1]) & (c[:, o[1]] > bounds[2])
                  & (c[:, o[1]] < bounds[3]))
        interior = np.all(fx[:, :, axis] > grids[axis][0] + tol, axis=1) & np.all(
            fx[:, :, axis] < grids[axis][-1] - tol, axis=1)
        surfaces[name] = faces[on & inside & interior]
    return surfaces


def box_mesh(size: Sequence[float], cells: Sequence[int], materials: Sequence[str] = ("soil",),
             interfaces: Sequence[float] = (), xs: ArrayLike | None = None, ys: ArrayLike | None = None,
             zs: ArrayLike | None = None, planes: Sequence[tuple] = ()) -> SerialMesh:
    """A box [0, lx] x [0, ly] x [-lz, 0] of ``cells`` hexahedra (or on the node coordinates ``xs``, ``ys``,
    ``zs``), six tetrahedra each; material k between interface depths k-1 and k (m, positive down); the outer
    sides as surfaces xmin, xmax, ymin, ymax, bottom, top, and the fault ``planes`` (parse_planes) as surfaces."""
    lx, ly, lz = size
    nx, ny, nz = (int(c) for c in cells)
    if min(nx, ny, nz) < 1 or min(lx, ly, lz) <= 0:
        raise InputError("-pfault_box_cells / -pfault_box_size: need positive sizes and at least one cell "
                         "per direction")
    if len(interfaces) != len(materials) - 1:
        raise InputError(f"-pfault_box_interfaces: {len(materials)} materials need {len(materials) - 1} "
                         f"interface depths, got {len(interfaces)}")
    grids = _node_planes(size, (nx, ny, nz), interfaces, xs, ys, zs, planes)
    points, tets = _kuhn_tets(*grids)
    centroid_depth = -points[tets, 2].mean(axis=1)
    cell_material = np.searchsorted(np.asarray(sorted(interfaces), float), centroid_depth)
    tol = 1e-9 * max(lx, ly, lz)
    surfaces = _outer_surfaces(points, tets, grids, tol)
    if planes:
        surfaces.update(_plane_surfaces(points, tets, planes, grids, tol))
    return SerialMesh(points=points, tets=tets, cell_material=cell_material.astype(np.int64),
                      material_names=list(materials), surfaces=surfaces, source="box").check()
