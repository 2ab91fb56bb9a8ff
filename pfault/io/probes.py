"""The displacement at given points of the mesh (stations, the pixels of an InSAR raster over the land surface),
in the P1 basis of the tetrahedron that contains each point.

Points are located once, on rank 0, in the serial mesh (partition-independent: the same cell and weights on any
number of ranks); each rank then evaluates the points whose cell it holds, from its local displacement, and
rank 0 sums the parts (every point is evaluated by exactly one rank, the others add zeros).

A point on a face shared by several cells takes the cell with the smallest serial id among them (the values
agree there, the P1 field being continuous), except on a fault: there the two sides differ, and the point takes
the side it asks for (minus by default: the side the fault's normal points away from, pfault.mesh.fault).

Coordinates: pfault's outputs and inputs of points are in site coordinates, which ``mesh_to_site`` maps to and
from the mesh's.
"""

from __future__ import annotations

from collections.abc import Sequence

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import check_raster_memory
from ..errors import InputError
from ..mesh.serial import TET_FACES, locate_faces

# barycentric coordinates down to -INSIDE_TOL count as inside a cell (a point on a face or an edge is in all
# the cells around it); the same tolerance says on which fault vertices a point has weight
INSIDE_TOL = 1e-9

SIDE_NAMES = ("", "minus", "plus")      # side codes: 0 not on a fault, 1 minus, 2 plus


def mesh_to_site(xyz: np.ndarray, origin: Sequence[float] = (0.0, 0.0, 0.0), inverse: bool = False) -> np.ndarray:
    """Site coordinates of points in mesh coordinates ((n, 3) or (n, 2) x, y); ``inverse``: mesh coordinates of
    points in site coordinates. Site = mesh + origin (-pfault_mesh_origin): every coordinate a station file gives
    and every coordinate pfault writes for stations and rasters goes through this function."""
    xyz = np.asarray(xyz, dtype=np.float64)
    shift = np.asarray(origin, dtype=np.float64)[:xyz.shape[-1]]
    return xyz - shift if inverse else xyz + shift


@dataclass(frozen=True)
class Located:
    """Points located in the serial mesh: serial ``cell`` (-1: outside the mesh), the P1 ``weights`` (n, 4) of
    the cell's vertices at the point, and the fault ``side`` taken (0 not on a fault, 1 minus, 2 plus)."""
    cell: np.ndarray
    weights: np.ndarray
    side: np.ndarray


def barycentric(x: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (m, 4) of the point x (3,) in the tetrahedra ``verts`` (m, 4, 3)."""
    t = np.transpose(verts[:, 1:] - verts[:, :1], (0, 2, 1))
    lam = np.linalg.solve(t, (x - verts[:, 0])[:, :, None])[:, :, 0]
    return np.column_stack([1.0 - lam.sum(axis=1), lam])


def locate_points(points: np.ndarray, tets: np.ndarray, xyz: np.ndarray, vert_sides: np.ndarray | None = None,
                  cell_side: np.ndarray | None = None, plus: np.ndarray | None = None) -> Located:
    """Locate the points ``xyz`` (n, 3, mesh coordinates) in the serial mesh (``points``, ``tets``); with faults,
    ``vert_sides`` and ``cell_side`` are the fault split's (pfault.mesh.fault.FaultSplit) and ``plus`` (n,) bool
    says which points on a fault take its plus side. Rank 0, NumPy only. The cells whose bounding box holds a
    point are searched in the slab of cells sorted by x whose centre is within the widest cell's width of it
    (100 points in a million cells: 1.1 s, the bounding boxes included; 8 s over every box)."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    n = len(xyz)
    corners = points[tets]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    pad = 1e-9 * max(float(np.ptp(points, axis=0).max()), 1.0)
    by_x = np.argsort(lo[:, 0] + hi[:, 0], kind="stable")
    centre_x = 0.5 * (lo[by_x, 0] + hi[by_x, 0])
    reach = 0.5 * float(np.max(hi[:, 0] - lo[:, 0])) + pad
    cell = np.full(n, -1, np.int64)
    weights = np.zeros((n, 4))
    side = np.zeros(n, np.int64)
    want_plus = np.zeros(n, bool) if plus is None else np.asarray(plus, bool)
    for i, x in enumerate(xyz):
        slab = by_x[np.searchsorted(centre_x, x[0] - reach):np.searchsorted(centre_x, x[0] + reach, side="right")]
        cand = slab[np.all((lo[slab] - pad <= x) & (x <= hi[slab] + pad), axis=1)]
        if not len(cand):
            continue
        lam = barycentric(x, corners[cand])
        inside = np.all(lam >= -INSIDE_TOL, axis=1)
        cand, lam = cand[inside], lam[inside]
        if not len(cand):
            continue
        code = _sides(tets[cand], lam, vert_sides, cell_side, cand)
        if (code == 1).any() and (code == 2).any():       # on a fault: the side asked for
            keep = code == (2 if want_plus[i] else 1)
            cand, lam, side[i] = cand[keep], lam[keep], 2 if want_plus[i] else 1
        j = int(np.argmin(cand))
        cell[i], weights[i] = cand[j], lam[j]
    return Located(cell, weights, side)


def _sides(tets, lam, vert_sides, cell_side, cells):
    """Per candidate cell: 0 when the point has no weight on a split fault vertex of it, else 1 (the cell uses
    the first piece's copies of those vertices) or 2 (another piece's: the plus side where one fault passes)."""
    if vert_sides is None:
        return np.zeros(len(tets), np.int64)
    split = (vert_sides[tets] > 1) & (lam > INSIDE_TOL)
    plus = (cell_side[cells] >= 1) & split
    return np.where(split.any(axis=1), np.where(plus.any(axis=1), 2, 1), 0)


@dataclass(frozen=True)
class Raster:
    x: np.ndarray               # (nx,) pixel centres, site coordinates
    y: np.ndarray               # (ny,) ascending
    inside: np.ndarray          # (ny, nx) bool: the pixel's centre is on the land surface


def ground_faces(serial: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(cell, local face) of the land surface's triangles in the serial mesh: those of the physical surface
    ``name``, or the faces on the plane z = max z when the mesh has no such surface (pfault.hazard's rule)."""
    tri = serial.surfaces.get(name)
    if tri is not None and len(tri):
        t, cell, lface = locate_faces(serial.tets, len(serial.points), tri)
        _, first = np.unique(t, return_index=True)
        return cell[first], lface[first]
    z = serial.points[:, 2]
    on = np.abs(z - z.max()) <= 1e-9 * max(float(np.ptp(serial.points, axis=0).max()), 1.0)
    faces = serial.tets[:, TET_FACES]                               # (nc, 4, 3)
    cell, lface = np.nonzero(on[faces].all(axis=2))
    return cell, lface


def locate_pixels(serial: Any, ground: str, spacing: float | None,
                  origin: Sequence[float] = (0.0, 0.0, 0.0), ranks_on_node: int = 1,
                  memory: float | None = None) -> tuple[Raster, Located]:
    """Rank 0: the raster over the land surface and, for each pixel inside it (in row-major order of
    ``inside``), the tetrahedron under the surface triangle below its centre and the P1 weights there. A centre
    on an edge or a vertex shared by several triangles takes the one of the smallest cell id, as a station does.
    A raster that would not fit in the memory of this node (``ranks_on_node`` ranks on it) is an error before
    it is made (pfault.checks.check_raster_memory; ``memory``: the bytes it may take, None: what the node has)."""
    cell, lface = ground_faces(serial, ground)
    if not len(cell):
        raise InputError(f"-pfault_insar_los: the mesh has no land surface (-pfault_ground_surface {ground}, nor "
                         "faces on its top plane) to map")
    local = TET_FACES[lface]                                        # (m, 3) local vertices of each triangle
    tri = serial.tets[cell[:, None], local]
    xy = mesh_to_site(serial.points[:, :2], origin)
    p = xy[tri]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    flat = np.abs(area) > 1e-9 * np.abs(area).max()                 # vertical triangles cover no pixel
    cell, local, p = cell[flat], local[flat], p[flat]
    mean_edge = float(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).mean())
    spacing = mean_edge if spacing is None else spacing
    lo, hi = p.min(axis=(0, 1)), p.max(axis=(0, 1))
    with np.errstate(over="ignore"):
        check_raster_memory(np.ceil((hi - lo) / spacing) + 1, hi - lo, spacing, mean_edge, ranks_on_node,
                            memory)
    first = np.floor(lo / spacing + 1e-9) * spacing
    count = np.maximum(np.ceil((hi - first) / spacing - 1e-9).astype(np.int64), 1)
    x = first[0] + spacing * (np.arange(count[0]) + 0.5)
    y = first[1] + spacing * (np.arange(count[1]) + 0.5)
    pixel, k, lam = _pixels_in_triangles(p, first, spacing, count)
    order = np.lexsort((k, cell[k], pixel))                        # per pixel: the smallest cell id first
    pixel, k, lam = pixel[order], k[order], lam[order]
    one = np.r_[True, pixel[1:] != pixel[:-1]]
    pixel, k, lam = pixel[one], k[one], lam[one]
    inside = np.zeros(count[1] * count[0], bool)
    inside[pixel] = True
    weights = np.zeros((len(k), 4))
    weights[np.arange(len(k))[:, None], local[k]] = lam
    located = Located(cell[k].astype(np.int64), weights, np.zeros(len(k), np.int64))
    return Raster(x, y, inside.reshape(count[1], count[0])), located


def _pixels_in_triangles(p: np.ndarray, first: np.ndarray, spacing: float,
                         count: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (pixel, triangle) pair whose pixel centre is in the triangle (``p`` (m, 3, 2) its corners; pixel
    centres first + (i + 1/2) spacing, ``count`` (nx, ny) of them): the pixel's row-major index, the triangle and
    its barycentric coordinates (n, 3) there. The candidates are the pixels of each triangle's bounding box."""
    lo = np.ceil((p.min(axis=1) - first) / spacing - 0.5 - 1e-9).astype(np.int64)
    hi = np.floor((p.max(axis=1) - first) / spacing - 0.5 + 1e-9).astype(np.int64)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, count - 1)
    size = np.maximum(hi - lo + 1, 0)                               # (m, 2) pixels along x and y
    n = size[:, 0] * size[:, 1]
    k = np.repeat(np.arange(len(p)), n)
    r = np.arange(len(k)) - np.repeat(np.cumsum(n) - n, n)
    ix, iy = lo[k, 0] + r % size[k, 0], lo[k, 1] + r // size[k, 0]
    q = first + spacing * (np.column_stack([ix, iy]) + 0.5)
    a, b, c = p[k, 0], p[k, 1], p[k, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1 = ((q[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (q[:, 1] - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (q[:, 1] - a[:, 1]) - (q[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    lam = np.column_stack([1.0 - l1 - l2, l1, l2])
    keep = np.all(lam >= -INSIDE_TOL, axis=1)
    return (iy * count[0] + ix)[keep], k[keep], lam[keep]


class PointProbe:
    """Evaluates the displacement at located points on the distributed mesh. ``located`` (the same on every
    rank) holds every point's serial cell and weights; ``mesh`` and ``dofmap`` are the local mesh and its
    dofs. Collective."""

    def __init__(self, comm: Any, mesh: Any, dofmap: Any, located: Located) -> None:
        self.mpi = comm.tompi4py()
        self.n = len(located.cell)
        order = np.argsort(mesh.cell_serial)
        pos = np.minimum(np.searchsorted(mesh.cell_serial[order], located.cell), max(len(order) - 1, 0))
        local = order[pos] if len(order) else np.zeros(self.n, np.int64)
        mine = (located.cell >= 0) & (mesh.cell_serial[local] == located.cell) if len(order) else \
            np.zeros(self.n, bool)
        self.index = np.flatnonzero(mine)
        self.dofs = dofmap.cell_dofs[local[mine]].reshape(-1, 4, 3)     # the cell's side of a split vertex
        self.weights = located.weights[mine]
        count = self.mpi.allreduce(mine.astype(np.int64))
        if np.any(count[located.cell >= 0] != 1):
            raise RuntimeError("a located point is held by no rank or by several")

    def values(self, u_local: np.ndarray) -> np.ndarray | None:
        """(n, 3) displacement at the points on rank 0 (None elsewhere) from each rank's local array."""
        part = np.zeros((self.n, 3))
        part[self.index] = np.einsum("mk,mkc->mc", self.weights, u_local[self.dofs])
        if self.mpi.size == 1:
            return part
        from mpi4py import MPI
        total = np.zeros_like(part) if self.mpi.rank == 0 else None
        self.mpi.Reduce(part, total, op=MPI.SUM, root=0)
        return total
