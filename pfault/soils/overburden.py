"""The overburden of points of a tetrahedral mesh: the weight of the column above each point, by marching a vertical
ray up from the point through the cells it crosses (pure NumPy, on the serial mesh: the same numbers on any number of
ranks).

Along the vertical line through (x, y) the barycentric coordinates of a cell are affine in z, so the ray leaves a
cell where the first of them that falls with z reaches zero, through the face opposite that vertex, into the cell
across it; the cell adds its unit weight times the length of the ray inside it. A ray that leaves the mesh (the land
surface) is done. All rays advance one cell per pass, vectorised; a point's column is as many passes as cells above
it. Rays start at the points moved by 1e-9 of the mesh's extent off vertical mesh lines (pfault.soils.columns.nudged),
so that none runs along an edge or a face shared by several cells.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..mesh.serial import TET_FACES
from ..physics.elasticity import tet_geometry
from .columns import nudged


def face_neighbours(tets: np.ndarray) -> np.ndarray:
    """(nc, 4): the cell across the face opposite each local vertex of every cell (-1 on the mesh's boundary)."""
    nc = len(tets)
    faces = np.sort(tets[:, TET_FACES].reshape(-1, 3), axis=1).astype(np.int64)
    nv = int(tets.max(initial=0)) + 1
    if nv ** 3 < 2 ** 62:                  # a face as one integer: np.unique of rows is slower
        faces = (faces[:, 0] * nv + faces[:, 1]) * nv + faces[:, 2]
        _, inverse, counts = np.unique(faces, return_inverse=True, return_counts=True)
    else:
        _, inverse, counts = np.unique(faces, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    out = np.full(nc * 4, -1, np.int64)
    pair = counts[inverse[order]] == 2                      # the two sides of an interior face, adjacent in order
    a = order[pair][0::2]
    b = order[pair][1::2]
    out[a], out[b] = b // 4, a // 4
    return out.reshape(nc, 4)


def opposite_faces() -> np.ndarray:
    """The local vertex each face of TET_FACES leaves out (the face opposite it)."""
    return np.array([next(v for v in range(4) if v not in f) for f in TET_FACES])


def overburden(points: np.ndarray, cells: np.ndarray, coords: np.ndarray, tets: np.ndarray, grad: np.ndarray,
               unit_weight: np.ndarray) -> np.ndarray:
    """The weight (Pa) of the column above each point (m, 3) of cell ``cells`` (m,): the cells' unit weights (N/m^3)
    times the lengths of the upward vertical ray inside them. ``grad``: the cells' shape-function gradients."""
    nbr = face_neighbours(tets)[:, np.argsort(opposite_faces())]     # nbr[c, i]: across the face opposite vertex i
    lo, hi = coords[:, :2].min(axis=0), coords[:, :2].max(axis=0)
    xy = nudged(np.asarray(points, float)[:, :2], lo, hi)
    z = np.array(points, dtype=float)[:, 2].copy()
    cell = np.array(cells, dtype=np.int64).copy()
    weight = np.zeros(len(z))
    ray = np.arange(len(z))
    base = 1.0 - np.einsum("nik,nik->ni", grad, coords[tets])     # lambda_i(p) = base_i + g_i . p
    for _ in range(len(tets) + 1):
        if not len(ray):
            break
        c = cell[ray]
        g = grad[c]
        a = base[c] + g[:, :, 0] * xy[ray, 0][:, None] + g[:, :, 1] * xy[ray, 1][:, None]
        gz = g[:, :, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            exit_z = np.where(gz < 0, -a / gz, np.inf)
        k = np.argmin(exit_z, axis=1)
        top = np.maximum(exit_z[np.arange(len(c)), k], z[ray])
        weight[ray] += unit_weight[c] * (top - z[ray])
        z[ray] = top
        cell[ray] = nbr[c, k]
        ray = ray[cell[ray] >= 0]
    return weight


def initial_effective_stress(points: np.ndarray, tets: np.ndarray, cells: np.ndarray, density: np.ndarray,
                             alpha: np.ndarray, settings: Any) -> np.ndarray:
    """The initial vertical effective stress (Pa, compression positive) of the cells ``cells`` of a mesh (``points``,
    ``tets``; ``density``, ``alpha`` per cell): the overburden at the middle of each cell's vertical extent less
    alpha times the hydrostatic pore pressure there (the water table and gravity of ``settings``). The overburden
    is marched up from the cell's centroid (``overburden``) and carried to the middle of its extent with the cell's
    own density. The middle of the extent, not the centroid: the cells of a slab of a flat layer (every P1 cell of a
    hexahedron spans its height) then start from the same stress, and P1 holds the 1-D response exactly; from their
    centroids' stresses, in the ratios 1:2:3 under the land surface, they shared a drawdown unevenly, and Wuxi's
    land surface, 20 m cells under it far from the ridge, subsided by 0.90 to 1.55 m within 500 m (1.06-1.08 m with
    linear soils)."""
    corners = points[tets]
    grad, _ = tet_geometry(corners)
    g = settings.gravity
    centre = corners[cells].mean(axis=1)
    z = corners[cells][:, :, 2]
    middle = 0.5 * (z.min(axis=1) + z.max(axis=1))
    total = overburden(centre, cells, points, tets, grad, density * g) + density[cells] * g * (centre[:, 2] - middle)
    pore = settings.water_density * g * np.maximum(settings.water_table - middle, 0.0)
    return total - alpha[cells] * pore
